#!/bin/sh
# lib/gen_kinds_list.sh — the measurement kinds' list (beaconloc/kinds_list.h,
# included by beaconloc/kinds.h) from the kinds' own headers, so that no
# hand-written list names a kind (issue 10).
#
#   sh lib/gen_kinds_list.sh lib/include/beaconloc/aid_*.h > kinds_list.h
#
# Every header given is one kind, aid_<kind>.h, and declares its place in
# the list with one line
#     #define BL_<KIND>_KIND_ORDER <n>
# (<KIND>: <kind> in capitals; <n>: a decimal number, the list sorted by it,
# gaps allowed, two kinds with one <n> an error). Out: each header's
# #include and BL_KINDS(X, arg) with X(kind, KIND, arg) for every kind in
# that order, on stdout; errors on stderr, exit status 1. POSIX sh, sed,
# awk and sort only: the library builds for firmware without Python. Run
# by lib/lib.mk into the build directory at every build, never committed.
set -eu

entries=''
for h in "$@"; do
    kind=$(basename "$h" .h)
    kind=${kind#aid_}
    case $kind in
    '' | [!a-z]* | *[!a-z0-9_]*)
        echo "$h: a kind's header is aid_<kind>.h, <kind> a lower-case C name" >&2
        exit 1
        ;;
    esac
    KIND=$(printf '%s\n' "$kind" | tr 'a-z' 'A-Z')
    orders=$(awk -v name="BL_${KIND}_KIND_ORDER" '$1 == "#define" && $2 == name { print $3 }' "$h")
    case $orders in
    '')
        echo "$h: no '#define BL_${KIND}_KIND_ORDER <n>' (its place in the kinds' list)" >&2
        exit 1
        ;;
    *[!0-9]*)
        echo "$h: BL_${KIND}_KIND_ORDER must be defined once, as a decimal number (found:" $orders")" >&2
        exit 1
        ;;
    esac
    entries="$entries$orders $kind $KIND $h
"
done

printf '%s' "$entries" | sort -n -k1,1 | awk '
    n && $1 == prev {
        printf "%s and %s: one place in the kinds'"'"' list (BL_<KIND>_KIND_ORDER %s)\n", prev_h, $4, $1 | "cat 1>&2"
        bad = 1
    }
    { prev = $1; prev_h = $4; n++; order[n] = $1; kind[n] = $2; KIND[n] = $3 }
    END {
        if (bad) exit 1
        print "/* beaconloc — the measurement kinds'"'"' list, generated at build time by"
        print " * lib/gen_kinds_list.sh from lib/include/beaconloc/aid_*.h (each one'"'"'s"
        print " * BL_<KIND>_KIND_ORDER gives its place): never edited, never committed."
        print " * Included by beaconloc/kinds.h, which documents it. */"
        print "#ifndef BEACONLOC_KINDS_LIST_H"
        print "#define BEACONLOC_KINDS_LIST_H"
        print ""
        for (i = 1; i <= n; i++) printf "#include \"beaconloc/aid_%s.h\"\n", kind[i]
        print ""
        print "/* Each header still declares the place it was listed at (a list older"
        print " * than its headers, or an order defined only under a build switch). */"
        for (i = 1; i <= n; i++) {
            printf "#if BL_%s_KIND_ORDER != %s\n", KIND[i], order[i]
            printf "#error \"aid_%s.h: BL_%s_KIND_ORDER is not %s, its place in this list: regenerate it\"\n", kind[i], KIND[i], order[i]
            print "#endif"
        }
        print ""
        print "/* X(kind, KIND, arg) for every kind, in BL_<KIND>_KIND_ORDER. */"
        printf "#define BL_KINDS(X, arg)"
        for (i = 1; i <= n; i++) printf " \\\n    X(%s, %s, arg)", kind[i], KIND[i]
        print ""
        print ""
        print "#endif /* BEACONLOC_KINDS_LIST_H */"
    }'
