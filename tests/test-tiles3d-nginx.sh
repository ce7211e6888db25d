#!/usr/bin/env bash
# The 3D Tiles provider against a real server: nginx (Debian nginx-light)
# on 127.0.0.1, a free port, a temporary config (daemon off, every path in
# a temporary folder, the current user), serving a baked folder; stopped at
# the end. Skipped (77) without nginx. Faults through the config, on the
# cells around the street path's start (it heads along +z from the corner
# of cell 0,0; the baked rectangle starts at cell -3,-3):
#   content/3/3/3.glb  cell 0,0   404  -> refused at once, no retry
#   content/3/2/3.glb  cell -1,0  500  -> retried 3 times, then refused
#   content/3/3/2.glb  cell 0,-1  444 (the connection closed without an
#                                 answer) -> the same
#   content/3/3/4.glb  cell 0,1   limit_rate 2k/s -> timed out
#                                 (--http-timeout 500), refused
# Each is a refusal with its cause in the world's log line (its
# TW_TILE_REFUSED event): under --policy wait the frame goes on once the
# tile is refused (every cause checked); under --policy skip the frames are
# drawn with holes meanwhile, at a real-time pace (the walk may end before
# the slow refusals: the 404's is checked); the walk ends with status 0, within a bound
# (timeout), and summary.json counts the four refusals (tile_cache.refused)
# and the provider's failures (tiles3d.failures). Then ETag revalidation: a second walk with
# --http-cache gets 304s and serves them from the cache. A fetch still
# coming when the walk ends leaves its worker behind: the walk ends with
# status 0 all the same. Then the server
# stopped mid-walk: the walk goes on, serves what its cache holds (stale
# copies), refuses what it cannot fetch, and ends.
# Usage: test-tiles3d-nginx.sh TILEWORLD
set -u
tw=$1
nginx=$(command -v nginx || echo /usr/sbin/nginx)
[ -x "$nginx" ] || { echo "no nginx (Debian nginx-light): skipped"; exit 77; }
. "$(dirname "$0")/test-lib.sh"
pid=
stop() {
    if [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null; then
        kill "$pid" 2>/dev/null
        wait "$pid" 2>/dev/null
    fi
    pid=
}
trap "stop; [ -n \"${KEEP:-}\" ] || rm -rf $tmp" EXIT
fail() { bad "$@"; }

"$tw" bake --tileset city-gen --cells -3,-3:2,2 --out "$tmp/site" --workers 2 --quiet ||
    { echo "FAIL: the bake failed"; exit 1; }
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
user_line=
[ "$(id -u)" = 0 ] && user_line="user $(id -un) $(id -gn);"
mkdir -p "$tmp/nginx"
cat >"$tmp/nginx.conf" <<EOF
daemon off;
master_process off;
worker_processes 1;
$user_line
pid $tmp/nginx/nginx.pid;
error_log $tmp/nginx/error.log;
events { worker_connections 64; }
http {
    access_log $tmp/nginx/access.log;
    client_body_temp_path $tmp/nginx/body;
    proxy_temp_path $tmp/nginx/proxy;
    fastcgi_temp_path $tmp/nginx/fastcgi;
    uwsgi_temp_path $tmp/nginx/uwsgi;
    scgi_temp_path $tmp/nginx/scgi;
    types { application/json json; model/gltf-binary glb; application/octet-stream subtree; }
    server {
        listen 127.0.0.1:$port;
        root $tmp/site;
        etag on;
        location = /content/3/3/3.glb { return 404; }
        location = /content/3/2/3.glb { return 500; }
        location = /content/3/3/2.glb { return 444; }
        location = /content/3/3/4.glb { limit_rate 2k; }
    }
}
EOF
start() {
    "$nginx" -c "$tmp/nginx.conf" -p "$tmp/nginx" -e "$tmp/nginx/error.log" \
        >"$tmp/nginx/stdout" 2>&1 &
    pid=$!
    for _ in $(seq 50); do
        curl -s -o /dev/null "http://127.0.0.1:$port/tileset.json" 2>/dev/null && return 0
        python3 -c "import socket,sys; s=socket.socket(); sys.exit(s.connect_ex(('127.0.0.1', $port)))" && return 0
        sleep 0.1
    done
    echo "FAIL: nginx did not start: $(cat "$tmp/nginx/error.log" "$tmp/nginx/stdout" 2>/dev/null)"
    exit 1
}
start
url="http://127.0.0.1:$port/tileset.json"
walk=(walk --tileset "$url" --view-distance 150 --png-every 0 --size 160x90 --workers 2
      --http-timeout 500)
# Under skip a frame does not wait: the camera stands at the start for
# 1000 frames paced at 100 a second (--fps), at least 10 s whatever a frame
# costs (a frame with holes costs next to nothing: unpaced, the walk could
# end before the tiles were asked for), long enough that the refusals (up
# to 4 x 0.5 s and the back-off) come before the walk ends.
{
    echo cell_i,cell_j,x,y,z,yaw,pitch
    yes 0,0,0.5,1.7,0.5,0,0 | head -n 1000
} >"$tmp/still.csv"

causes() {  # FILE: the refusals' causes it must name
    local f=$1
    grep -q "content/3/3/3.glb: HTTP 404" "$f" && ok || fail "$2: no 404 refusal: $(grep -i error "$f" | head -3)"
    grep -q "content/3/2/3.glb: HTTP 500 after 4 attempts" "$f" && ok || fail "$2: no 500 refusal"
    grep -q "content/3/3/2.glb: .* after 4 attempts" "$f" && ok || fail "$2: no refusal of the closed connection"
    grep -q "content/3/3/4.glb: Timeout was reached" "$f" && ok || fail "$2: no refusal of the slow tile"
}

for policy in skip wait; do
    path=(--frames 30)
    [ "$policy" = skip ] && path=(--path "$tmp/still.csv" --fps 100)
    timeout 60 "$tw" "${walk[@]}" "${path[@]}" --policy "$policy" --out "$tmp/$policy" >"$tmp/$policy.out" 2>"$tmp/$policy.err"
    rc=$?
    [ "$rc" = 0 ] || fail "--policy $policy: exit status $rc: $(tail -3 "$tmp/$policy.err")"
    # Under skip the walk may end before the slow refusals come (it waits
    # for nothing): the 404 at least; under wait, every cause.
    if [ "$policy" = wait ]; then
        causes "$tmp/$policy.err" "--policy $policy"
    else
        grep -q "content/3/3/3.glb: HTTP 404" "$tmp/$policy.err" && ok ||
            fail "--policy skip: no 404 refusal: $(grep -i error "$tmp/$policy.err" | head -3)"
    fi
    grep "3D Tiles:" "$tmp/$policy.err" | tail -1
    # summary.json counts them: the world's refusals, the provider's failures.
    if [ "$policy" = wait ]; then
        refused=$(sed -n 's/.*"refused": \([0-9]*\).*/\1/p' "$tmp/$policy/summary.json")
        failures=$(sed -n 's/.*"failures": \([0-9]*\).*/\1/p' "$tmp/$policy/summary.json")
        { [ -n "$refused" ] && [ "$refused" -ge 4 ]; } && ok ||
            fail "summary.json's tile_cache.refused is ${refused:-missing}, not 4 or more"
        { [ -n "$failures" ] && [ "$failures" -ge 4 ]; } && ok ||
            fail "summary.json's tiles3d.failures is ${failures:-missing}, not 4 or more"
    fi
done
grep -c "3/3/3.glb" "$tmp/nginx/access.log" | awk '{ exit !($1 >= 1) }' || fail "the 404 was never asked for"

# A fetch that outlasts the world: the slow tile with a timeout of minutes
# is still coming when a short walk ends, so its worker is left behind at
# the destroy (after 5 s). The program keeps the provider that worker is
# in, says so, and ends at once with status 0 (no exit-time destructors
# under a running thread).
head -n 41 "$tmp/still.csv" >"$tmp/short.csv"
timeout 60 "$tw" walk --tileset "$url" --view-distance 150 --png-every 0 --size 160x90 --workers 2 \
    --http-timeout 600000 --path "$tmp/short.csv" --fps 10 --policy skip --out "$tmp/left" \
    >"$tmp/left.out" 2>"$tmp/left.err"
rc=$?
[ "$rc" = 0 ] || fail "the walk leaving a fetch behind exits $rc: $(tail -3 "$tmp/left.err")"
# (The slow tile's, and any other still in a step that does not stop.)
grep -q "gave up after 5.0 s waiting for [0-9]* tile workers\? still generating (cells .*(0, 1)" "$tmp/left.err" && ok ||
    fail "no worker left behind on the slow tile: $(grep -i error "$tmp/left.err" | head -3)"
grep -q "[0-9]* tile workers\? still in the provider's generate(): ending without waiting for" "$tmp/left.err" && ok ||
    fail "no line on the worker left behind: $(tail -3 "$tmp/left.err")"

# ETag revalidation.
cache=$tmp/cache
timeout 60 "$tw" "${walk[@]}" --frames 30 --policy wait --http-cache "$cache" --out "$tmp/c1" >/dev/null 2>"$tmp/c1.err" && ok ||
    fail "the first cached walk fails: $(tail -3 "$tmp/c1.err")"
timeout 60 "$tw" "${walk[@]}" --frames 30 --policy wait --http-cache "$cache" --out "$tmp/c2" >/dev/null 2>"$tmp/c2.err" && ok ||
    fail "the second cached walk fails: $(tail -3 "$tmp/c2.err")"
line=$(grep "3D Tiles: .* requests" "$tmp/c2.err" | tail -1)
echo "second run: $line"
n304=$(sed -n 's/.* \([0-9]*\) not modified (304).*/\1/p' <<<"$line")
hits=$(sed -n 's/.* \([0-9]*\) cache hits.*/\1/p' <<<"$line")
{ [ -n "$n304" ] && [ "$n304" -ge 10 ]; } && ok || fail "the second run got ${n304:-no} 304s: $line"
[ "${hits:-0}" = "$n304" ] && ok || fail "304s not served from the cache: $line"
ls "$cache"/*.twc >/dev/null 2>&1 && ok || fail "the cache holds no file"
# A byte limit below one tile's size keeps the cache under it.
timeout 60 "$tw" "${walk[@]}" --frames 30 --policy wait --http-cache "$cache" --http-cache-bytes 100K \
    --out "$tmp/c3" >/dev/null 2>"$tmp/c3.err" && ok || fail "the walk with a small cache fails"
bytes=$(du -sb "$cache" | cut -f1)
[ "$bytes" -le $((100 * 1024 + 4096)) ] && ok || fail "the cache holds $bytes bytes over a limit of 100K"

# The server stopped mid-walk: once the walk has fetched a few tiles. The
# cache holds the first 20 frames' tiles (a walk before): those are served
# from it once the server is gone (stale-if-error), the others refused.
stale=$tmp/stale-cache
timeout 60 "$tw" walk --tileset "$url" --frames 20 --view-distance 150 --png-every 0 \
    --size 160x90 --workers 1 --policy wait --http-timeout 500 --http-cache "$stale" --out "$tmp/fill" \
    >/dev/null 2>"$tmp/fill.err" && ok || fail "the walk filling the cache fails"
: >"$tmp/nginx/access.log"
timeout 60 "$tw" walk --tileset "$url" --frames 60 --view-distance 150 --png-every 0 \
    --size 160x90 --workers 1 --policy wait --http-timeout 500 --http-cache "$stale" \
    --out "$tmp/stop" >"$tmp/stop.out" 2>"$tmp/stop.err" &
walker=$!
for _ in $(seq 100); do
    [ "$(grep -c '\.glb' "$tmp/nginx/access.log" 2>/dev/null)" -ge 4 ] && break
    sleep 0.05
done
stop
wait "$walker"
rc=$?
[ "$rc" = 0 ] || fail "the walk whose server stopped exits $rc: $(tail -3 "$tmp/stop.err")"
grep -q "Couldn't connect to server after 4 attempts" "$tmp/stop.err" && ok ||
    fail "no refusal after the server stopped: $(tail -5 "$tmp/stop.err")"
line=$(grep "3D Tiles:" "$tmp/stop.err" | tail -1)
echo "server stopped: $line"
n=$(sed -n 's/.* \([0-9]*\) stale copies.*/\1/p' <<<"$line")
{ [ -n "$n" ] && [ "$n" -ge 1 ]; } && ok || fail "no stale copy served from the cache once the server stopped: $line"

echo "faults refused with their causes, 304s from the cache, a stopped server survived"
finish tiles3d-nginx
