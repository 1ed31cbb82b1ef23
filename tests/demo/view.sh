#!/bin/sh
# make demo, the live map: starts beaconloc-view on the host in the background, following
# the bridge's MAVLink frames that tests/demo/demo.py (in the guest, which has no network
# to the host) appends to DIR/mavlink.raw, and says where the page is. The viewer stops by
# itself LINGER seconds after the last message (the page keeps the run's end until then).
#   view.sh DIR PORT LINGER
set -u
dir=$1 port=$2 linger=$3
cd "$(dirname "$0")/../.."
state=$(dirname "$dir")/demo-view
mkdir -p "$dir"
# a viewer of an earlier make demo (ours, by its pid file) gives the port back
if [ -f "$state.pid" ]; then
    pid=$(cat "$state.pid")
    if [ "$(cat /proc/"$pid"/comm 2>/dev/null)" = "beaconloc-view" ]; then
        kill "$pid" 2>/dev/null
        sleep 0.5
    fi
    rm -f "$state.pid"
fi
rm -f "$dir/mavlink.raw" "$state.url"
start() {
    nohup .venv/bin/beaconloc-view --scenario kleeman-lab --follow "$dir/mavlink.raw" \
        --port "$1" --exit-idle "$linger" --url-file "$state.url" >"$state.log" 2>&1 &
    echo $! >"$state.pid"
    i=0
    while [ $i -lt 100 ] && [ ! -s "$state.url" ] && kill -0 "$(cat "$state.pid")" 2>/dev/null; do
        sleep 0.1; i=$((i + 1))
    done
    [ -s "$state.url" ]
}
if start "$port" || start 0; then
    echo "demo: live map at $(cat "$state.url") (open it in a browser; beaconloc-view, log $state.log)"
else
    echo "demo: beaconloc-view did not start (see $state.log); the demo goes on without it"
fi
exit 0
