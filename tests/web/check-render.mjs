// node check-render.mjs [--min-drawn=F] RESULT.json EXPECTED_URI...
// Judges what render-tileset.mjs printed: the tiles drawn are exactly the
// EXPECTED_URIs (relative content URIs), each where the client's implicit
// tiling puts its tile, no error anywhere (page, loader, console, server),
// and a picture of the palette's colours. Prints one line per failure and
// a summary line; exit status 1 on any failure. --min-drawn: the least
// fraction of the pixels that must differ from the clear colour (0.05; a
// tenth of it must be coloured).
import fs from 'node:fs';

const args = process.argv.slice(2);
let minDrawn = 0.05;
if (args.length && args[0].startsWith('--min-drawn='))
    minDrawn = Number(args.shift().slice('--min-drawn='.length));
const [file, ...expected] = args;
const r = JSON.parse(fs.readFileSync(file, 'utf8'));
const failures = [];
const check = (ok, what) => { if (!ok) failures.push(what); };
// 3DTilesRendererJS says this of every 1.1 tileset, ours or not.
const known = /tiles versions at 1\.1 or higher have limited support/;

check(r.done, 'the page did not finish');
for (const e of r.errors)
    failures.push(`page: ${e}`);
for (const m of r.console)
    check(known.test(m), `console: ${m}`);
for (const q of r.requests)
    check(q.startsWith('200 '), `server: ${q}`);
check(r.stats.failed === 0, `${r.stats.failed} tiles failed to load`);
const want = [...expected].sort();
const got = r.visibleContent;
check(JSON.stringify(got) === JSON.stringify(want),
      `drawn ${got.length} tiles [${got.join(' ')}], expected ${want.length} [${want.join(' ')}]`);
check(r.drawnTiles === want.length, `${r.drawnTiles} tiles drew meshes, expected ${want.length}`);
for (const m of r.misplaced)
    failures.push(`misplaced: ${m}`);
const p = r.picture;
check(p.drawnFraction >= minDrawn, `only ${p.drawnFraction} of the pixels differ from the clear colour`);
check(p.colouredFraction >= minDrawn / 10, `only ${p.colouredFraction} of the pixels are coloured`);
check(p.inPaletteFraction >= 0.9, `only ${p.inPaletteFraction} of the coloured pixels have a hue of the tiles' colours (COLOR_0 and materials)`);
check(p.paletteHuesSeen >= 2, `${p.paletteHuesSeen} hues of the palette seen`);
for (const f of failures)
    console.log(`FAIL: ${f}`);
console.log(`${got.length} tiles drawn (${r.drawnTriangles} triangles), ${(100 * p.drawnFraction).toFixed(1)} % of the ` +
            `pixels drawn, ${(100 * p.colouredFraction).toFixed(1)} % coloured, ${p.paletteHuesSeen} palette hues, ` +
            `${r.frames} frames; ${failures.length} failures`);
process.exit(failures.length ? 1 : 0);
