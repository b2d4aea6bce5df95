#!/bin/sh
# What a bridge's link needs, checked before the build (called by `make check-sdk`):
#   tools/sdk-prereqs.sh CC "SYMBOLS" HEADERS-VERSION LINK-FLAGS...
# links a program that references every function the bridge calls (SYMBOLS, the vendor's
# library's) with the build's own link flags, then loads it. If the link fails, each -lNAME
# is tried alone, and every library the linker cannot use, or that a vendor's shared library
# needs and the system lacks, is named with what provides it (a Debian package, or the
# vendor's installer); a function the library lacks is named with the headers' version
# (HEADERS-VERSION) and, for Force Dimension's, the version the library itself says it is:
# a library older than its headers. Exit 0 when the link works and loads, 1 otherwise.
set -u
cc=$1 headers=$3
# shellcheck disable=SC2086
symbols=$(printf '%s ' $2) # one line, each name once followed by a space
shift 3
dir=$(mktemp -d) || exit 1
trap 'rm -rf "$dir"' EXIT
{
    for s in $symbols; do printf 'void %s(void);\n' "$s"; done
    printf 'void (*const hl_probe[])(void) = {'
    for s in $symbols; do printf '%s, ' "$s"; done
    printf '};\nint main(void) { return hl_probe[0] == 0; }\n'
} > "$dir/probe.c"

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
        found="" here=""
        for f in "$@"; do
            case $f in
                -L*)
                    [ -z "$here" ] && [ -e "${f#-L}/$lib" ] && here=${f#-L}
                    [ -z "$found" ] && ls "${f#-L}/$lib".* > /dev/null 2>&1 && found=${f#-L}
                    ;;
            esac
        done
        if [ -n "$here" ]; then
            # the link is there: the loader is not told to look in that folder
            echo "missing: $lib, which the bridge loads at run time: $here holds $lib, but" \
                "the loader does not look there: the link flags need -Wl,-rpath,$here (the" \
                "Makefile's own DHD_LIBS and HD_LIBS have it)"
        elif [ -n "$found" ]; then
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
# a function the bridge calls that the library lacks: "undefined reference to `X'"
if [ "$missing" = 0 ]; then
    lacks=""
    for s in $symbols; do
        grep -q "undefined reference to .$s'" "$dir/log" && lacks="$lacks $s"
    done
    if [ -n "$lacks" ]; then
        missing=1
        for s in $lacks; do
            echo "missing: the SDK's library lacks $s, which the SDK's headers ($headers)" \
                "declare and the bridge calls"
        done
        case " $symbols " in
            *" dhdGetSDKVersion "*)
                # what the library says it is (every libdhd has dhdGetSDKVersion)
                printf '%s\n' '#include <stdio.h>' \
                    'void dhdGetSDKVersion(int *, int *, int *, int *);' \
                    'int main(void) { int a = 0, b = 0, c = 0, d = 0;' \
                    '    dhdGetSDKVersion(&a, &b, &c, &d); printf("%d.%d.%d\n", a, b, c); return 0; }' \
                    > "$dir/version.c"
                if "$cc" -o "$dir/version" "$dir/version.c" "$@" > /dev/null 2>&1 &&
                    lib=$("$dir/version") && [ -n "$lib" ]; then
                    case $headers in
                        "$lib" | "$lib"-*) echo "the library says it is $lib, as its headers:" \
                            "it lacks what they declare; reinstall the SDK" ;;
                        *) older=$(printf '%s\n%s\n' "$lib" "$headers" | sort -V | head -1)
                           if [ "$older" = "$lib" ]; then
                               echo "the library is older than its headers: it says it is $lib" \
                                   "(dhdGetSDKVersion); install one SDK version's headers and" \
                                   "library together"
                           else
                               echo "the library is not its headers' version: it says it is" \
                                   "$lib (dhdGetSDKVersion); install one SDK version's headers" \
                                   "and library together"
                           fi ;;
                    esac
                fi
                ;;
            *) echo "the library is older than its headers, or another SDK's: install one" \
                   "version's headers and library together" ;;
        esac
    fi
fi
if [ "$missing" = 0 ]; then
    echo "the link with $* fails:"
    sed 's/^/  /' "$dir/log" | head -20
fi
exit 1
