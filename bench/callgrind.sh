#!/bin/bash
# Instruction counts that do not depend on machine noise: valgrind's callgrind over any program of the build.
# libjxl (pulled in through OpenImageIO) loads libhwy, whose copy runs `rdtscp` at load time, which valgrind
# rejects; this script builds an empty stand-in for libhwy.so.1 once (nothing here calls Highway) and puts it
# first on LD_LIBRARY_PATH for the run only. Everything after the script name goes to valgrind.
# usage: bench/callgrind.sh [valgrind options] PROGRAM [ARGS]
#   e.g. bench/callgrind.sh --toggle-collect=srv__compose build/bench/bench_stages --no-scaling --warmup 2 --frames 5
set -euo pipefail
if [ $# -eq 0 ] || [ "$1" = "--help" ] || [ "$1" = "-h" ]; then
    sed -n '2,7p' "$0" | sed 's/^# \{0,1\}//'
    exit $(($# == 0 ? 2 : 0))
fi
command -v valgrind >/dev/null || { echo "callgrind.sh: valgrind is not installed (apt-get install valgrind)" >&2; exit 1; }
stub=${FXC_HWY_STUB_DIR:-${TMPDIR:-/tmp}/fxcache-hwy-stub-$(id -u)}
if [ ! -f "$stub/libhwy.so.1" ]; then
    mkdir -p "$stub"
    echo 'void fxc_hwy_stub(void) {}' > "$stub/stub.c"
    cc -shared -fPIC -o "$stub/libhwy.so.1" "$stub/stub.c" -Wl,-soname,libhwy.so.1 ||
        { echo "callgrind.sh: could not build the libhwy stand-in in $stub" >&2; exit 1; }
fi
LD_LIBRARY_PATH="$stub${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}" exec valgrind --tool=callgrind "$@"
