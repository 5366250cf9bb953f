#!/bin/sh
# Proves that a program is the lightweight viewer client: it needs no Embree, Assimp, OpenMesh or TBB library
# of its own (readelf -d: the libraries it names), loads no Embree, Assimp or OpenMesh through any library
# (ldd; TBB is left out there because OpenImageIO itself loads it), and holds no code of the server's modules
# (nm: no scene_, srv_, osc_, wsc_ or fx_ symbol). Prints each finding on its own line; exit 0 when there is
# none, 1 when there is one, 2 when the program cannot be examined (so the check cannot pass by not looking).
# Usage: check_links.sh PROGRAM      (the ctest viewer_links runs it on fxcache-viewer)
set -u
program=$1
if [ ! -x "$program" ]; then
    echo "$program: not an executable"
    exit 2
fi
needed=$(readelf -d "$program" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p')
symbols=$(nm "$program" 2>/dev/null | awk '{ print $NF }')
if [ -z "$needed" ] || ! printf '%s\n' "$symbols" | grep -qx main; then
    echo "$program: cannot read its dynamic section or its symbols (readelf -d, nm): nothing proven"
    exit 2
fi
status=0
for library in $needed; do
    case $library in
    *embree* | *assimp* | *OpenMesh* | *tbb*)
        echo "$program: needs $library"
        status=1
        ;;
    esac
done
for library in $(ldd "$program" | awk '{ print $1 }' | grep -i -E 'embree|assimp|openmesh'); do
    echo "$program: loads $library through its libraries"
    status=1
done
server_symbols=$(printf '%s\n' "$symbols" | grep -E '^(scene|srv|osc|wsc|fx)_' | sort -u)
if [ -n "$server_symbols" ]; then
    echo "$program: holds $(printf '%s\n' "$server_symbols" | wc -l) symbols of the server's modules:" \
        $(printf '%s\n' "$server_symbols" | head -n 5)
    status=1
fi
if [ $status = 0 ]; then
    echo "$program: needs $(echo $needed | wc -w) libraries, none of Embree, Assimp, OpenMesh or TBB;" \
        "no scene_, srv_, osc_, wsc_ or fx_ symbols"
fi
exit $status
