// Draws the tileset named by ?tileset= with 3DTilesRendererJS (three.js) and
// leaves in window.result what test-bake-chromium.sh checks: the tiles drawn
// (content URIs), the renderer's stats, the load errors, and figures of the
// picture (pixels unlike the clear colour, their hues against the palette of
// the tiles' COLOR_0).
//
// ?tileset=URL    tileset.json
// ?error=PX       the renderer's errorTarget (screen-space error in pixels)
// ?distance=F     the camera's distance in bounding-sphere radii (default 2.2)
import * as THREE from 'three';
import { TilesRenderer } from '3d-tiles-renderer/three';
import { ImplicitTilingPlugin } from '3d-tiles-renderer/core/plugins';
import { pictureFigures } from './picture.js';

const params = new URLSearchParams(location.search);
const tilesetUrl = params.get('tileset');
const errorTarget = Number(params.get('error') ?? 16);
const distance = Number(params.get('distance') ?? 2.2);
const width = 800, height = 600;
const clearColour = new THREE.Color(0x000000);

const result = { done: false, errors: [], loadedModels: [], paletteHues: [] };
window.result = result;
const fail = (what) => { result.errors.push(String(what)); };
window.addEventListener('error', (e) => fail(`page error: ${e.message}`));
window.addEventListener('unhandledrejection', (e) => fail(`unhandled rejection: ${e.reason}`));

// The camera from the root's bounding volume: the box's centre and the
// radius of its sphere, in the root transform's frame; z is up there.
function cameraFromRoot(json) {
    const root = json.root;
    const box = root.boundingVolume.box;
    if (!box)
        throw new Error('the root has no box bounding volume');
    const m = new THREE.Matrix4();
    if (root.transform)
        m.fromArray(root.transform);
    const centre = new THREE.Vector3(box[0], box[1], box[2]).applyMatrix4(m);
    const axes = [0, 1, 2].map((i) => new THREE.Vector3(box[3 + 3 * i], box[4 + 3 * i], box[5 + 3 * i]));
    const radius = axes.reduce((s, a) => s.add(a), new THREE.Vector3()).length() || 1;
    const camera = new THREE.PerspectiveCamera(50, width / height, radius / 100, radius * 100);
    camera.up.set(0, 0, 1);
    // From the south-east (cells run along +x and -y), 40 degrees up.
    const dir = new THREE.Vector3(0.35, -0.55, 0.6).normalize();
    camera.position.copy(centre).addScaledVector(dir, radius * distance);
    camera.lookAt(centre);
    camera.updateMatrixWorld();
    return { camera, centre, radius };
}

// The hues (degrees) of the distinct colours in a loaded glTF scene whose
// chroma is not small: its COLOR_0 attributes (the small instances the
// library merges) times their material's colour, and the colours of the
// materials of meshes without COLOR_0 (the instances drawn as they are).
function addPaletteHues(scene, hues) {
    const c = new THREE.Color();
    const add = () => {
        const hsl = c.getHSL({});
        const chroma = Math.max(c.r, c.g, c.b) - Math.min(c.r, c.g, c.b);
        if (chroma > 0.1)
            hues.add(Math.round(hsl.h * 360));
    };
    scene.traverse((o) => {
        if (!o.isMesh)
            return;
        const m = o.material && o.material.color ? o.material.color : new THREE.Color(1, 1, 1);
        const colours = o.geometry && o.geometry.getAttribute('color');
        if (!colours) {
            c.copy(m);
            add();
            return;
        }
        for (let i = 0; i < colours.count; i++) {
            c.setRGB(colours.getX(i) * m.r, colours.getY(i) * m.g, colours.getZ(i) * m.b);
            add();
        }
    });
}


// Where a drawn tile's content lies against the box that the client derived
// for the tile from the root's box and the tile's implicit coordinates: the
// content's axis-aligned bounds, in the tileset's frame, must lie inside the
// box (1 cm of slack) and cover at least 90 % of its footprint. A message,
// or null when it does.
function placement(tile, group) {
    const b = tile.boundingVolume && tile.boundingVolume.box;
    const scene = tile.engineData && tile.engineData.scene;
    if (!b || !scene)
        return `${tile.content.uri}: no box or no scene`;
    const toTileset = new THREE.Matrix4().copy(group.matrixWorld).invert();
    const content = new THREE.Box3();
    scene.updateMatrixWorld(true);
    scene.traverse((o) => {
        if (o.isMesh) {
            o.geometry.computeBoundingBox();
            const m = new THREE.Matrix4().multiplyMatrices(toTileset, o.matrixWorld);
            content.union(o.geometry.boundingBox.clone().applyMatrix4(m));
        }
    });
    const m = new THREE.Matrix4();
    if (tile.implicitTilingData && tile.implicitTilingData.root.transform)
        m.fromArray(tile.implicitTilingData.root.transform);
    const box = new THREE.Box3();
    const c = new THREE.Vector3(b[0], b[1], b[2]);
    for (let corner = 0; corner < 8; corner++) {
        const p = c.clone();
        for (let i = 0; i < 3; i++) {
            const s = corner & (1 << i) ? 1 : -1;
            p.x += s * b[3 + 3 * i]; p.y += s * b[4 + 3 * i]; p.z += s * b[5 + 3 * i];
        }
        box.expandByPoint(p.applyMatrix4(m));
    }
    const fmt = (x) => `[${x.min.toArray().map((v) => v.toFixed(2))} .. ${x.max.toArray().map((v) => v.toFixed(2))}]`;
    const slack = box.clone().expandByScalar(0.01);
    const overlap = content.clone().intersect(box);
    const area = (x) => Math.max(0, x.max.x - x.min.x) * Math.max(0, x.max.y - x.min.y);
    if (!slack.containsBox(content) || area(overlap) < 0.9 * area(box))
        return `${tile.content.uri}: content ${fmt(content)} against the tile's box ${fmt(box)}`;
    return null;
}

async function main() {
    const json = await (await fetch(tilesetUrl)).json();
    const { camera, centre, radius } = cameraFromRoot(json);
    result.camera = { position: camera.position.toArray(), target: centre.toArray(), radius };

    const canvas = document.getElementById('view');
    const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
    renderer.setPixelRatio(1);
    renderer.setSize(width, height);
    renderer.setClearColor(clearColour);
    const scene = new THREE.Scene();
    scene.add(new THREE.AmbientLight(0xffffff, 1.2));
    const sun = new THREE.DirectionalLight(0xffffff, 2.0);
    sun.position.set(0.4, -0.3, 1);
    scene.add(sun);

    const tiles = new TilesRenderer(tilesetUrl);
    tiles.registerPlugin(new ImplicitTilingPlugin());
    tiles.errorTarget = errorTarget;
    tiles.setCamera(camera);
    tiles.setResolutionFromRenderer(camera, renderer);
    scene.add(tiles.group);

    const paletteHues = new Set();
    let loadEnds = 0;
    tiles.addEventListener('load-model', (e) => {
        result.loadedModels.push(e.url ?? e.tile?.content?.uri);
        addPaletteHues(e.scene, paletteHues);
    });
    tiles.addEventListener('load-error', (e) => fail(`load-error ${e.url}: ${e.error?.message ?? e.error}`));
    tiles.addEventListener('tiles-load-end', () => loadEnds++);

    // Render until a load has ended and nothing is queued, downloading or
    // parsing for 10 frames in a row.
    let quiet = 0, frames = 0;
    await new Promise((resolve) => {
        const frame = () => {
            frames++;
            tiles.update();
            renderer.render(scene, camera);
            const s = tiles.stats;
            const busy = s.queued + s.downloading + s.parsing;
            quiet = loadEnds > 0 && busy === 0 && tiles.loadProgress === 1 ? quiet + 1 : 0;
            if (quiet >= 10 || frames > 20000)
                resolve();
            else
                requestAnimationFrame(frame);
        };
        requestAnimationFrame(frame);
    });

    const visible = [];
    const misplaced = [];
    tiles.group.updateMatrixWorld(true);
    for (const t of tiles.visibleTiles) {
        if (!(t.content && t.content.uri))
            continue;
        visible.push(t.content.uri);
        const place = placement(t, tiles.group);
        if (place)
            misplaced.push(place);
    }
    visible.sort();
    // The tiles whose content has a mesh (a tile holds one glTF node per
    // drawn instance, a mesh each).
    let drawnTiles = 0;
    for (const t of tiles.visibleTiles) {
        const sc = t.content && t.content.uri && t.engineData && t.engineData.scene;
        let any = false;
        if (sc)
            sc.traverse((o) => { any = any || o.isMesh; });
        drawnTiles += any ? 1 : 0;
    }
    let drawnMeshes = 0, drawnTriangles = 0;
    tiles.group.traverse((o) => {
        if (o.isMesh && o.visible) {
            let shown = true;
            for (let p = o; p; p = p.parent)
                shown = shown && p.visible;
            if (shown) {
                drawnMeshes++;
                drawnTriangles += (o.geometry.index ? o.geometry.index.count : o.geometry.getAttribute('position').count) / 3;
            }
        }
    });
    const stats = {};
    for (const [k, v] of Object.entries(tiles.stats))
        if (typeof v === 'number')
            stats[k] = v;
    Object.assign(result, {
        frames, loadEnds, misplaced, stats, visibleContent: visible, drawnTiles, drawnMeshes, drawnTriangles,
        paletteHues: [...paletteHues].sort((a, b) => a - b),
        picture: pictureFigures(canvas, [clearColour.r * 255, clearColour.g * 255, clearColour.b * 255], paletteHues),
        done: true,
    });
}

main().catch((e) => { fail(`main: ${e && e.stack || e}`); result.done = true; });
