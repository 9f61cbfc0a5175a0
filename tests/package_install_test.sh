#!/usr/bin/env bash
# The Debian package's install test: the .deb unpacked into a temporary root (dpkg-deb -x), its files where the unit
# and the example configuration expect them, the unit with its drop-in verified by systemd-analyze in that root, the
# maintainer scripts creating the user the unit runs as, the shared libraries' packages in Depends, and the program
# running from the unpacked tree. Needs no root and no network; scripts/package-chroot-test installs the package for
# real (dpkg -i in a debootstrapped chroot).
#
#   tests/package_install_test.sh --build-dir BUILD   # packages BUILD first (cpack, no rebuild): ctest runs this
#   tests/package_install_test.sh --deb FILE.deb      # a package made already (scripts/package)
set -euo pipefail
# A command that stops the script under set -e names itself, so a run never ends without saying which check broke.
trap 'echo "FAIL: line $LINENO: $BASH_COMMAND exited with $?"' ERR

usage() { echo "usage: $0 --build-dir BUILD | --deb FILE.deb" >&2; exit 2; }
[ $# -eq 2 ] || usage
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

failures=0
ok() { echo "ok: $*"; }
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }
check() {  # check DESCRIPTION COMMAND...: ok when COMMAND succeeds
  local what=$1; shift
  if "$@"; then ok "$what"; else fail "$what"; fi
}

case $1 in
  --build-dir)
    # The package of the program already built there: cpack installs into its own staging under $work.
    if ! cpack -G DEB --config "$2/CPackConfig.cmake" -B "$work/cpack" >"$work/cpack.log" 2>&1; then
      cat "$work/cpack.log"; echo "FAIL: cpack -G DEB in $2"; exit 1
    fi
    deb=$(ls "$work"/cpack/imubridge_*.deb) ;;
  --deb) deb=$2 ;;
  *) usage ;;
esac
echo "package: $deb"
root="$work/root"
control="$work/control"
dpkg-deb -x "$deb" "$root"
dpkg-deb -e "$deb" "$control"

# The unit, and the paths its lines name.
unit="$root/usr/lib/systemd/system/imubridge.service"
dropin="$root/usr/lib/systemd/system/imubridge.service.d/system-user.conf"
check "the unit is in /usr/lib/systemd/system" test -f "$unit"
check "the system-user drop-in is beside it" test -f "$dropin"
unit_value() { sed -n "s/^$1=//p" "$unit" "$dropin" | tail -1; }  # the drop-in's value wins, as in systemd
exec_start=$(unit_value ExecStart)
read -r binary _ <<<"$exec_start"
check "ExecStart's program $binary is in the package and executable" test -x "$root$binary"
config=$(sed -n 's/.*--config \([^ ]*\).*/\1/p' <<<"$exec_start")
check "ExecStart's configuration $config is in the package" test -f "$root$config"
check "$config is a conffile" grep -qx "$config" "$control/conffiles"
documentation=$(unit_value Documentation)
check "Documentation=$documentation is in the package" test -f "$root${documentation#file://}"
state_dir=/var/lib/$(unit_value StateDirectory)
db=$(sed -n 's/^path = "\(.*\)".*/\1/p' "$root$config" | head -1)
check "the example configuration's store ($db) is in the unit's StateDirectory ($state_dir)" \
  test "$(dirname "$db")" = "$state_dir"
runtime_dir=/run/$(unit_value RuntimeDirectory)
socket=$(sed -n 's|.*"unix://\([^"]*\)".*|\1|p' "$root$config" | head -1)
check "the example configuration's line stream ($socket) is in the unit's RuntimeDirectory ($runtime_dir)" \
  test "$(dirname "$socket")" = "$runtime_dir"
for doc in README.md copyright operations.md config.md outputs.md replay.md storage.md; do
  check "/usr/share/doc/imubridge/$doc is in the package" test -f "$root/usr/share/doc/imubridge/$doc"
done

# The user: the drop-in runs the service as the user that postinst creates, with the state directory its own.
user=$(unit_value User)
check "the unit runs as a static user (DynamicUser=no)" test "$(unit_value DynamicUser)" = no
check "the unit's user is imubridge" test "$user" = imubridge
check "postinst creates $user as a system user (adduser --system)" \
  grep -Eq "^[[:space:]]*adduser --system .*[[:space:]]$user\$" "$control/postinst"
check "postinst makes $state_dir owned by $user" \
  grep -Eq "install -d -o $user -g $user -m $(unit_value StateDirectoryMode) $state_dir" "$control/postinst"
for script in postinst prerm postrm; do
  check "$script is executable and valid sh" bash -c "test -x '$control/$script' && sh -n '$control/$script'"
done
depends=$(sed -n 's/^Depends: //p' "$control/control")
check "Depends names adduser, which postinst runs" grep -q '\badduser\b' <<<"$depends"
read -r reload _ <<<"$(unit_value ExecReload)"
reload_owner=$(dpkg -S "$reload" 2>/dev/null | cut -d: -f1 | head -1 || true)
check "Depends names ${reload_owner:-the package of $reload}, whose $reload ExecReload runs" \
  grep -q "\b${reload_owner:-unknown}\b" <<<"$depends"

# Every shared library the program needs comes from a package in Depends (CPACK_DEBIAN_PACKAGE_SHLIBDEPS). The
# library's package is looked up on this machine, under the path ldconfig gives and the one it resolves to (merged
# /usr: a package owns one of the two).
depends_names=$(sed 's/ ([^)]*)//g; s/ | /\n/g; s/, /\n/g' <<<"$depends")
while read -r library; do
  # awk reads all of ldconfig's list: leaving early would end ldconfig with SIGPIPE, which pipefail makes fatal.
  path=$(ldconfig -p | awk -v l="$library" '$1 == l && path == "" { path = $NF } END { print path }')
  owner=""
  for candidate in "$path" "$(readlink -f "$path")"; do
    [ -n "$owner" ] || owner=$(dpkg -S "$candidate" 2>/dev/null | cut -d: -f1 | head -1) || true
  done
  # The package, or a name it provides (libspdlog1.10 provides libspdlog1.10-fmt9, which its shlibs file names).
  names=$(printf '%s\n' "${owner:-unknown}"; dpkg-query -W -f='${Provides}' "$owner" 2>/dev/null |
    sed 's/ ([^)]*)//g; s/, /\n/g' || true)
  check "$library (package ${owner:-unknown}) is in Depends" grep -qxFf <(echo "$names") <<<"$depends_names"
done < <(objdump -p "$root$binary" | awk '$1 == "NEEDED" { print $2 }')

# The program runs from the unpacked tree, and is the version the package says.
package_version=$(sed -n 's/^Version: //p' "$control/control")
check "$binary --version prints the package's version ($package_version)" \
  test "$("$root$binary" --version)" = "$package_version"
check "the program is stripped" bash -c "! objdump -h '$root$binary' | grep -q '\.debug_info'"

# systemd-analyze verify in the unpacked root, with the drop-in. The root also needs the units the service's
# dependencies name (sysinit.target, ...) and ExecReload's /bin/kill, which every system with systemd has: they come
# from this machine. verify fails when ExecStart's program is missing from the root; it must print nothing.
mkdir -p "$root/lib/systemd" "$root/bin"
cp -a /lib/systemd/system "$root/lib/systemd/"
cp "$(type -P kill)" "$root/bin/kill"
if verify=$(systemd-analyze verify --root="$root" imubridge.service 2>&1) && [ -z "$verify" ]; then
  ok "systemd-analyze verify --root: no findings"
else
  fail "systemd-analyze verify --root: $verify"
fi
rm -f "$root$binary"
if systemd-analyze verify --root="$root" imubridge.service >/dev/null 2>&1; then
  fail "systemd-analyze verify passes without ExecStart's program: it checks nothing here"
else
  ok "systemd-analyze verify fails once ExecStart's program is removed (it does check the root)"
fi

if [ "$failures" -ne 0 ]; then
  echo "$failures check(s) failed"
  exit 1
fi
echo "all checks passed"
