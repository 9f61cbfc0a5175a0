// The properties of fuzz/xbee_fuzz.cpp, in API mode 2 (escaped).
#define IMUBRIDGE_XBEE_FUZZ_MODE escaped
#include "fuzz/xbee_fuzz.cpp"
