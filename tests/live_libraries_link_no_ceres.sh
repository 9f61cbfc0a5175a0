#!/usr/bin/env bash
# The live libraries link neither Ceres nor the offline fitting (identification/): only the program does, for its
# offline commands. Checked twice, because either can regress alone:
#   1. the link closure CMake computed at configure time names no Ceres, glog and no fitting library;
#   2. no object in a live archive references a Ceres or glog symbol, or a function the fitting library defines
#      (a live file calling a fit would link only through the program, and go unnoticed until a test linked it).
# Usage: live_libraries_link_no_ceres.sh FITTING_ARCHIVE 'LIBRARY:CLOSURE|...' LIVE_ARCHIVE...
set -euo pipefail
fitting_archive=$1
closures=$2
shift 2

failed=0
IFS='|' read -ra entries <<<"$closures"
for entry in "${entries[@]}"; do
  library=${entry%%:*}
  for linked in ${entry#*:}; do
    if [[ $linked =~ [Cc]eres|glog|imubridge_identification|imubridge_diagnose ]]; then
      echo "$library links $linked" >&2
      failed=1
    fi
  done
done

# Functions and data the fitting library defines (not weak: inline and template code is shared by everyone).
fitting_symbols=$(mktemp)
trap 'rm -f "$fitting_symbols"' EXIT
nm --defined-only --extern-only "$fitting_archive" | awk 'NF == 3 && $2 ~ /^[TDBR]$/ {print $3}' | sort -u \
  >"$fitting_symbols"
for archive in "$@"; do
  undefined=$(nm --undefined-only "$archive" | awk '{print $NF}' | sort -u)
  from_ceres=$(c++filt <<<"$undefined" | grep -E '^(ceres|google)::' || true)
  from_fitting=$(comm -12 <(echo "$undefined") "$fitting_symbols" | c++filt || true)
  if [[ -n $from_ceres || -n $from_fitting ]]; then
    echo "$(basename "$archive") references:" >&2
    printf '%s\n' $'\n'"$from_ceres" $'\n'"$from_fitting" | sed '/^$/d; s/^/  /' >&2
    failed=1
  fi
done
if ((failed == 0)); then echo "live libraries: no Ceres, no fitting ($# archives)"; fi
exit $failed
