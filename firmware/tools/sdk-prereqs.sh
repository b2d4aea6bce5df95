#!/bin/sh
# What a bridge's link needs, checked before the build (called by `make check-sdk`):
#   tools/sdk-prereqs.sh CC SYMBOL LINK-FLAGS...
# links a one-line program that calls SYMBOL (a function of the vendor's library) with the
# build's own link flags. If that fails, each -lNAME is tried alone, and every library the
# linker cannot use, or that a vendor's shared library needs and the system lacks, is named
# with what provides it (a Debian package, or the vendor's installer). Exit 0 when the link
# works, 1 otherwise.
set -u
cc=$1 symbol=$2
shift 2
dir=$(mktemp -d) || exit 1
trap 'rm -rf "$dir"' EXIT
printf 'void %s(void);\nint main(void) { %s(); return 0; }\n' "$symbol" "$symbol" > "$dir/probe.c"

provider() {
    case $1 in
        usb-1.0|libusb-1.0.so*) echo "Debian's libusb-1.0-0-dev (apt-get install libusb-1.0-0-dev)" ;;
        stdc++|libstdc++.so*) echo "Debian's g++ (apt-get install g++)" ;;
        ncurses|libncurses.so.5*) echo "Debian's libncurses5 (apt-get install libncurses5)" ;;
        libPHANToMIO.so*|PHANToMIO) echo "the Touch device driver from 3D Systems (not in Debian: install their driver for your device)" ;;
        HD|libHD.so*) echo "OpenHaptics (its installer puts libHD in <prefix>/lib or <prefix>/lib64)" ;;
        drd|dhd) echo "the Force Dimension SDK (lib/release/lin-x86_64-gcc in its folder)" ;;
        *) echo "the package that provides lib$1" ;;
    esac
}

if "$cc" -o "$dir/probe" "$dir/probe.c" "$@" > "$dir/log" 2>&1; then
    # it links; does it load? A vendor's library installed outside the loader's folders
    # (OpenHaptics' tarball into /usr/lib64) lacks the link its soname names until ldconfig
    # makes it there
    status=0
    for lib in $(ldd "$dir/probe" 2>/dev/null | sed -n 's/^[[:space:]]*\([^ ]*\) => not found.*/\1/p'); do
        status=1
        found=""
        for f in "$@"; do
            case $f in
                -L*) [ -z "$found" ] && ls "${f#-L}/$lib".* > /dev/null 2>&1 && found=${f#-L} ;;
            esac
        done
        if [ -n "$found" ]; then
            echo "missing: $lib, which the bridge loads at run time: $found holds only" \
                "$(cd "$found" && ls "$lib".* | head -1); make the link with" \
                "\`ldconfig -n $found\` (as root), as the vendor's installer does in the" \
                "loader's own folders"
        else
            echo "missing: $lib, which the bridge loads at run time: install $(provider "$lib")"
        fi
    done
    exit $status
fi
missing=0
dirs=""
for f in "$@"; do
    case $f in -L*) dirs="$dirs $f" ;; esac
done
for f in "$@"; do
    case $f in
        -l*)
            name=${f#-l}
            printf 'int main(void) { return 0; }\n' > "$dir/empty.c"
            # shellcheck disable=SC2086
            if ! "$cc" -o "$dir/empty" "$dir/empty.c" $dirs "$f" > "$dir/one" 2>&1; then
                echo "missing: the linker finds no lib$name ($f): install $(provider "$name")"
                missing=1
            fi
            ;;
    esac
done
# a vendor's shared library that needs one the system lacks: "libX.so.N, needed by ..."
for need in $(sed -n 's/.*: \(lib[^ ,]*\), needed by .*/\1/p' "$dir/log" | sort -u); do
    echo "missing: $need, which the vendor's library needs: install $(provider "$need")"
    missing=1
done
if [ "$missing" = 0 ]; then
    echo "the link with $* fails:"
    sed 's/^/  /' "$dir/log" | head -20
fi
exit 1
