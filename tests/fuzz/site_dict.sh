#!/bin/sh
# libFuzzer dictionary for fuzz_site: every [section] and key of the site
# file's key table (bridge/config.c NUM/STR rows and bridge/tuning.h X rows),
# plus INI syntax. Usage: site_dict.sh bridge/config.c bridge/tuning.h
set -eu
config_c=$1
tuning_h=$2
{
    sed -n 's/.*\(NUM\|STR\)("\([a-zA-Z0-9_]*\)", "\([a-zA-Z0-9_]*\)".*/\2\n\3/p' "$config_c"
    sed -n 's/.*{ "beaconN", "\([a-z_]*\)".*/\1/p' "$config_c"
    sed -n 's/^[[:space:]]*X(\([a-z0-9_]*\),.*/\1/p' "$tuning_h"
    printf '%s\n' site beacon1 beacon6 beacon16 beacon17
} | sort -u | while read -r w; do
    case $w in
    beacons|receivers|robot|noise|tuning|bridge|site|beacon[0-9]*) printf '"[%s]\\x0a"\n' "$w" ;;
    *) printf '"%s = "\n' "$w" ;;
    esac
done
printf '%s\n' '"\x0a"' '" = "' '";"' '"#"' '"1e308"' '"-1e-308"' '"nan"' '"inf"' \
    '"0x1p-1074"' '"udpin:0.0.0.0:14550"' '"serial:/dev/ttyS0:57600"' '"debug"'
