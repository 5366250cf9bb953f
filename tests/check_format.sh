#!/bin/sh
# Checks that C and C++ sources follow the one .clang-format (CONVENTIONS.md): runs clang-format on each and
# names every file whose formatting differs, with the first differing lines. Exit 0 when none differs, 1 when
# one does, 2 when nothing could be checked (no clang-format, no files), so the check cannot pass by not looking.
# Usage: check_format.sh SOURCE_DIR            every tracked *.c, *.h, *.cpp, *.hpp of the checkout
#        check_format.sh SOURCE_DIR FILE...    those files, formatted with SOURCE_DIR's .clang-format
# Fix with: clang-format -i FILE...   (ctest format runs the first form on the source tree)
set -u
root=$1
shift
if ! command -v clang-format >/dev/null 2>&1; then
    echo "SKIP: clang-format is not installed (install-deps.sh installs it)"
    exit 2
fi
if [ ! -f "$root/.clang-format" ]; then
    echo "$root: no .clang-format: nothing checked"
    exit 2
fi
if [ $# -eq 0 ]; then
    if ! files=$(git -C "$root" ls-files '*.c' '*.h' '*.cpp' '*.hpp') || [ -z "$files" ]; then
        echo "$root: not a git checkout or no C/C++ files tracked: nothing checked"
        exit 2
    fi
    set -- $files
    cd "$root" || exit 2
fi
tmp=$(mktemp) || exit 2
status=0
checked=0
for file in "$@"; do
    if [ ! -r "$file" ]; then
        echo "$file: cannot be read"
        status=1
        continue
    fi
    checked=$((checked + 1))
    # --assume-filename: the style of the source tree's .clang-format, wherever the file lies.
    name=$(basename "$file")
    if ! clang-format --style=file --assume-filename="$root/$name" <"$file" | diff -u "$file" - >"$tmp" 2>&1; then
        echo "$file: differs from clang-format (clang-format -i $file); first lines:"
        sed -n '3,12p' "$tmp"
        status=1
    fi
done
rm -f "$tmp"
echo "check_format: $checked file(s) checked"
exit $status
