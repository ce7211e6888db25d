#!/usr/bin/env bash
# Results a user can trust at a glance: walk and bench end with a verdict on
# stdout (--quiet or not); under --verify a conservative method that misses
# a pixel makes the exit status 3 (--allow-missed: 0, said loudly either
# way); summary.md opens with the verdict and what ran, and says "not
# measured" where accuracy was not; a file name from input reaches no
# report or terminal raw; --split's parts add up and are never negative;
# import --help is help.
set -u
tw=${1:?usage: test-verdict.sh PATH/TO/tileworld}
. "$(dirname "$0")/test-lib.sh"

# Full detail: the verdicts do not depend on the levels, which a process
# showing the city builds first (about 3 s; ten under AddressSanitizer).
small=(--size 160x90 --png-every 0 --quiet --max-screen-error 0)

# ---- walk: a verdict on stdout, absolute figures, ratios left to bench ----------
if "$tw" walk --frames 6 "${small[@]}" --out "$tmp/walk" >"$tmp/out" 2>"$tmp/err"; then
    lines=$(wc -l <"$tmp/out")
    [ "$lines" -ge 2 ] && [ "$lines" -le 6 ] && ok || bad "walk: $lines verdict lines: $(cat "$tmp/out")"
    grep -q '^tileworld walk with tilequery+chc: tileset city, path street, 160x90, 6 frames' "$tmp/out" &&
        ok || bad "walk verdict: what ran: $(head -1 "$tmp/out")"
    grep -Eq ' through (osmesa|egl-[a-z]+) ' "$tmp/out" && ok || bad "walk verdict: no context kind"
    grep -Eq '^tilequery\+chc: [0-9.]+ ms of CPU time a frame, [0-9.]+ ms to a finished frame' "$tmp/out" &&
        grep -q 'need them in the same run: tileworld bench' "$tmp/out" && ok ||
        bad "walk verdict: figures: $(cat "$tmp/out")"
    grep -qx 'Accuracy not measured (add --verify).' "$tmp/out" && ok || bad "walk verdict: accuracy"
    [ ! -s "$tmp/err" ] && ok || bad "walk --quiet wrote on stderr: $(cat "$tmp/err")"
    grep -q '"missed_pixels_total": null' "$tmp/walk/summary.json" && ok ||
        bad "summary.json without --verify: missed pixels not null"
    grep -Eq '"peak_instance_bytes": [1-9]' "$tmp/walk/summary.json" &&
        grep -Eq '"peak_tile_cache_bytes": [1-9]' "$tmp/walk/summary.json" &&
        ! grep -q '"peak_cache_bytes"' "$tmp/walk/summary.json" && ok ||
        bad "summary.json: cache figures: $(grep peak "$tmp/walk/summary.json")"
else
    bad "walk failed: $(cat "$tmp/err")"
fi
# Without --quiet the "wrote" line is on stderr, the verdict still on stdout.
"$tw" walk --frames 2 --size 160x90 --png-every 0 --out "$tmp/loud" >"$tmp/out" 2>"$tmp/err"
grep -q '^tileworld: wrote ' "$tmp/err" && ! grep -q 'wrote' "$tmp/out" &&
    grep -q '^tileworld walk with ' "$tmp/out" && ok || bad "walk: stdout/stderr: $(cat "$tmp/out" "$tmp/err")"

# ---- bench: the fastest conservative method, against vfc and the box oracle -----
methods=vfc,chc,tilequery+chc,box-oracle
if "$tw" bench --frames 6 --methods $methods "${small[@]}" --out "$tmp/bench" >"$tmp/out" 2>"$tmp/err"; then
    lines=$(wc -l <"$tmp/out")
    [ "$lines" -ge 3 ] && [ "$lines" -le 6 ] && ok || bad "bench: $lines verdict lines: $(cat "$tmp/out")"
    grep -q '^tileworld bench of 4 methods: tileset city, path street, 160x90, 6 frames' "$tmp/out" && ok ||
        bad "bench verdict: what ran: $(head -1 "$tmp/out")"
    grep -Eq "^Fastest conservative method, by (CPU time|time to a finished frame \(wall\)): (vfc|chc|tilequery\+chc), [0-9.]+ ms .*\(([0-9.e-]+)x vfc's, [0-9.e-]+x the box oracle's\)" "$tmp/out" &&
        ok || bad "bench verdict: no fastest method with its ratios: $(cat "$tmp/out")"
    grep -q 'The next fastest, ' "$tmp/out" && ok || bad "bench verdict: by how much"
    grep -Eq "^(CPU|Wall) time per frame, as a multiple of vfc's / the box oracle's: vfc 1 / " "$tmp/out" &&
        grep -q 'box-oracle [0-9.e-]* / 1 (a limit)' "$tmp/out" && ok ||
        bad "bench verdict: every method's ratios: $(cat "$tmp/out")"
    grep -qx 'Accuracy not measured (add --verify).' "$tmp/out" && ok || bad "bench verdict: accuracy"
    # summary.md: the title, the verdict, what ran, then the tables.
    md=$tmp/bench/summary.md
    first_table=$(grep -n '^|' "$md" | head -1 | cut -d: -f1)
    ran=$(grep -n '^Ran on ' "$md" | head -1 | cut -d: -f1)
    fastest=$(grep -n '^Fastest conservative method' "$md" | head -1 | cut -d: -f1)
    [ -n "$fastest" ] && [ -n "$ran" ] && [ -n "$first_table" ] && [ "$fastest" -lt "$ran" ] &&
        [ "$ran" -lt "$first_table" ] && [ "$fastest" -le 4 ] && ok ||
        bad "summary.md does not open with the verdict and what ran: $(head -8 "$md")"
    sed -n "${ran}p" "$md" | grep -Eq 'through [a-z-]+; [a-z]+ build of [0-9a-z-]+; tileset city, path street, 160x90, 6 frames, seed 1\.$' &&
        ok || bad "summary.md: what ran: $(sed -n "${ran}p" "$md")"
    grep -q 'Accuracy not measured (add --verify)' "$md" && ok || bad "summary.md: accuracy not said"
    # No cell reads 0 missed pixels when nothing was measured.
    awk -F' \\| ' '/^\| method \|/ { c = 0; for (i = 1; i <= NF; i++) if ($i == "missed pixels") c = i; next }
                   c && /^\| (vfc|chc|tilequery\+chc|box-oracle) \|/ { n++; if ($c != "not measured") bad++ }
                   END { exit !(n == 4 && bad == 0) }' "$md" && ok ||
        bad "summary.md: missed pixels without --verify: $(grep '^| ' "$md" | head -6)"
else
    bad "bench failed: $(cat "$tmp/err")"
fi

# ---- --verify: missed pixels of a conservative method are exit status 3 ---------
broken=(bench --frames 6 --methods chc,tilequery+chc "${small[@]}" --verify --mutate-query-shrink 0.3)
"$tw" "${broken[@]}" --out "$tmp/broken" >"$tmp/out" 2>"$tmp/err"
rc=$?
[ "$rc" -eq 3 ] && ok || bad "a broken culler under --verify exited $rc (expected 3): $(cat "$tmp/err")"
grep -q '^FAILED: a conservative method missed pixels under --verify: .* missed [1-9][0-9]* pixels in [1-9][0-9]* of 6 frames.*Exit status 3' "$tmp/out" &&
    ok || bad "the verdict does not say the failure loudly: $(cat "$tmp/out")"
grep -q 'Testing only: every query box shrunk by 0.3' "$tmp/out" && ok || bad "verdict: mutation not said"
grep -q '^\*\*FAILED: ' "$tmp/broken/summary.md" && ok || bad "summary.md: failure not said loudly"
[ -f "$tmp/broken/summary.json" ] && [ -f "$tmp/broken/summary.md" ] && ok || bad "a failed check left no summaries"
"$tw" "${broken[@]}" --allow-missed --out "$tmp/allowed" >"$tmp/out" 2>"$tmp/err"
rc=$?
[ "$rc" -eq 0 ] && ok || bad "--allow-missed exited $rc (expected 0): $(cat "$tmp/err")"
grep -q '^FAILED: .*Accepted by --allow-missed' "$tmp/out" && ok || bad "--allow-missed: verdict: $(cat "$tmp/out")"
"$tw" walk --method chc --frames 6 "${small[@]}" --verify --mutate-query-shrink 0.3 --out "$tmp/wbroken" \
    >"$tmp/out" 2>"$tmp/err"
rc=$?
[ "$rc" -eq 3 ] && grep -q '^FAILED: ' "$tmp/out" && ok || bad "walk with a broken culler exited $rc: $(cat "$tmp/out")"
# The same culler unbroken: every pixel drawn, exit 0, and it is said.
"$tw" walk --method chc --frames 6 "${small[@]}" --verify --out "$tmp/fine" >"$tmp/out" 2>"$tmp/err"
rc=$?
[ "$rc" -eq 0 ] && grep -q '^Accuracy (--verify, .*): chc missed no pixel\.' "$tmp/out" && ok ||
    bad "walk --verify exited $rc: $(cat "$tmp/out" "$tmp/err")"
grep -Eq '"missed_pixels_total": 0' "$tmp/fine/summary.json" && ok || bad "summary.json: verified 0 missed"

# ---- a hostile file name: bad UTF-8, a bidi override, Markdown syntax ------------
name=$(printf '%s/#x\xff\xe2\x80\xae|`<b>*_ \033[31m.csv' "$tmp")
printf 'cell_i,cell_j,x,y,z,yaw,pitch\n0,0,0,1.7,3,0,0\n0,0,0,1.7,4,10,0\n0,0,0,1.7,5,20,0\n' >"$name"
if "$tw" bench --path "$name" --methods chc,oracle "${small[@]}" --out "$tmp/hostile" >"$tmp/out" 2>"$tmp/err"; then
    ok
    for f in "$tmp/hostile/summary.md" "$tmp/hostile/summary.json" "$tmp/out"; do
        iconv -f UTF-8 -t UTF-8 "$f" >/dev/null 2>&1 && ok || bad "$(basename "$f"): not valid UTF-8"
        if grep -q $'\xe2\x80\xae' "$f"; then bad "$(basename "$f"): a raw U+202E"; else ok; fi
        if LC_ALL=C grep -q $'\033' "$f"; then bad "$(basename "$f"): a raw escape character"; else ok; fi
    done
    python3 -c 'import json, sys; json.load(open(sys.argv[1], encoding="utf-8"))' "$tmp/hostile/summary.json" &&
        ok || bad "summary.json does not parse as UTF-8 JSON"
    # In summary.md the name is one piece of text: no table cell, code span, tag or heading from it.
    title=$(head -1 "$tmp/hostile/summary.md")
    case $title in
    '# tileworld bench: city, path '*'\#x\\xff\\u202e&#124;&#96;&lt;b&gt;\*\_ \\x1b'*) ok ;;
    *) bad "summary.md title: $title" ;;
    esac
    grep 'xff' "$tmp/hostile/summary.md" | grep -q '[|`<]' &&
        bad "summary.md: Markdown syntax from the name: $(grep xff "$tmp/hostile/summary.md")" || ok
    grep -q '#x\\\\xff\\\\u202e|`<b>\*_ \\\\x1b' "$tmp/hostile/summary.json" && ok ||
        bad "summary.json: the path: $(grep '"path"' "$tmp/hostile/summary.json")"
else
    bad "bench over a hostile file name: $(cat "$tmp/err")"
fi

# ---- --split: the parts add up, none is negative -----------------------------
if "$tw" bench --frames 6 --methods chc,tilequery+chc,oracle --split "${small[@]}" --out "$tmp/split" \
      >"$tmp/out" 2>"$tmp/err"; then
    python3 - "$tmp/split/summary.json" <<'EOF' && ok || bad "--split figures do not add up"
import json, sys
d = json.load(open(sys.argv[1]))
fail = 0
for m, o in d["methods"].items():
    s = o["set"]
    frame, drawing = s["mean_frame_cpu_ms"], s["mean_cpu_ms"]
    if s["frames"] != 5 or frame <= 0 or drawing <= 0:
        print(m, "frames or times", s); fail = 1
    if s["finding"] == "measured":
        ok = s["mean_finding_cpu_ms"] > s["finding_margin_cpu_ms"] >= 0 and \
             abs(drawing + s["mean_finding_cpu_ms"] - frame) <= 0.002
    elif s["finding"] == "not told apart from nothing":
        ok = s["mean_finding_cpu_ms"] is None and 0 <= s["finding_at_most_cpu_ms"] <= frame
    elif s["finding"] == "not measurable":
        ok = s["mean_finding_cpu_ms"] is None and drawing > frame
    elif s["finding"] == "too noisy to tell":
        ok = s["mean_finding_cpu_ms"] is None and s["finding_at_most_cpu_ms"] is None
    else:
        ok = False
    if not ok:
        print(m, s); fail = 1
sys.exit(fail)
EOF
    # The table: a row per method, no negative figure, never a set above its frame.
    table=$(sed -n '/^| method | frames compared/,/^$/p' "$tmp/split/summary.md")
    [ "$(grep -c '^| \(chc\|tilequery+chc\|oracle\) | 5 | ' <<<"$table")" -eq 3 ] && ok || bad "split table rows: $table"
    if grep -q -- '-[0-9]' <<<"$table"; then bad "a negative part: $table"; else ok; fi
    awk -F' \\| ' '/^\| (chc|tilequery\+chc|oracle) \|/ && $4 ~ /^[0-9.]+$/ && $4 + 0 > $3 + 0 { exit 1 }' <<<"$table" &&
        ok || bad "a set above its frame: $table"
else
    bad "bench --split: $(cat "$tmp/err")"
fi

# ---- help -----------------------------------------------------------------
for h in --help -h; do
    if "$tw" import $h >"$tmp/out" 2>"$tmp/err" && grep -q '^usage: tileworld import FILE.gltf|FILE.glb' "$tmp/out" &&
       [ ! -s "$tmp/err" ]; then ok; else bad "import $h: $(cat "$tmp/out" "$tmp/err")"; fi
done
"$tw" --help >"$tmp/help"
for p in street flyover forest teleport spin straight wander; do
    grep -q "\b$p\b" <(sed -n '/^--path/,/^--frames/p' "$tmp/help") && ok || bad "--help: --path does not name $p"
done
grep -q 'K, M, G or T' "$tmp/help" && grep -q -- '--allow-missed' "$tmp/help" && ok ||
    bad "--help: byte suffixes or --allow-missed missing"
for c in walk bench info; do
    "$tw" $c --help >"$tmp/out" 2>"$tmp/err" && head -1 "$tmp/out" | grep -q "^usage: tileworld $c " && ok ||
        bad "$c --help: $(head -2 "$tmp/out")"
done

finish test-verdict
