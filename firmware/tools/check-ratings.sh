#!/bin/sh
# The lab's BRIDGE_RATINGS, word by word, before anything is compiled (called by `make dhd`
# and `make hd`): each of the device's three ratings exactly once and with a value, and
# nothing else (a misspelled name would otherwise build, unused). The values' ranges are the
# device core's to check (src/device.c), which the Makefile compiles next.
#   tools/check-ratings.sh TARGET "$(BRIDGE_RATINGS)"
# Exit 0 when they are whole, 2 otherwise, each problem named.
set -u -f
target=$1 ratings=$2
page="docs/howto/run-on-your-device.md"
names="HL_EFFECTIVE_MASS_MG HL_CURRENT_RATING_MA HL_ENCODER_NM"
if [ -z "$ratings" ]; then
    echo "make $target needs BRIDGE_RATINGS='-DHL_EFFECTIVE_MASS_MG=... -DHL_CURRENT_RATING_MA=..." \
        "-DHL_ENCODER_NM=...', each from the device's data sheet: $page says which and how"
    exit 2
fi
bad=0
for w in $ratings; do
    case $w in
        -DHL_EFFECTIVE_MASS_MG=* | -DHL_CURRENT_RATING_MA=* | -DHL_ENCODER_NM=*)
            if [ -z "${w#*=}" ]; then
                echo "BRIDGE_RATINGS: $w has no value"
                bad=1
            fi
            ;;
        *)
            echo "BRIDGE_RATINGS: $w is not a rating (the three are $names)"
            bad=1
            ;;
    esac
done
for n in $names; do
    count=0
    for w in $ratings; do
        case $w in -D"$n"=*) count=$((count + 1)) ;; esac
    done
    if [ "$count" = 0 ]; then
        echo "BRIDGE_RATINGS lacks $n: a real device's build has no default"
        bad=1
    elif [ "$count" = 2 ]; then
        echo "BRIDGE_RATINGS names $n twice"
        bad=1
    elif [ "$count" -gt 2 ]; then
        echo "BRIDGE_RATINGS names $n $count times"
        bad=1
    fi
done
if [ "$bad" != 0 ]; then
    echo "make $target: each rating comes from the device's data sheet: $page says which and how"
    exit 2
fi
