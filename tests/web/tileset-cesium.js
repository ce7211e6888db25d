// Draws the tileset named by ?tileset= with CesiumJS (no globe, no imagery,
// nothing from outside) and leaves in window.result what
// test-bake-chromium.sh checks: the tiles drawn (content URIs), the
// tileset's statistics, the errors, and figures of the picture.
//
// ?tileset=URL    tileset.json
// ?error=PX       the tileset's maximumScreenSpaceError
// The tileset's frame is put east-north-up at 8.54 E, 47.37 N (the README's
// way to put a bake on the globe); the camera is placed from the root's box
// as on 3DTilesRendererJS's page.
import { pictureFigures } from './picture.js';

const Cesium = window.Cesium;
const params = new URLSearchParams(location.search);
const tilesetUrl = params.get('tileset');
const errorTarget = Number(params.get('error') ?? 16);
const result = { done: false, errors: [], loadedModels: [] };
window.result = result;
const fail = (what) => { result.errors.push(String(what)); };
window.addEventListener('error', (e) => fail(`page error: ${e.message}`));
window.addEventListener('unhandledrejection', (e) => fail(`unhandled rejection: ${e.reason}`));
const relative = (url) => String(url).replace(/^.*\/tileset\//, '');

async function main() {
    const widget = new Cesium.CesiumWidget('view', {
        baseLayer: false, globe: false, skyBox: false, skyAtmosphere: false, shadows: false,
        creditContainer: 'credits', msaaSamples: 1, useBrowserRecommendedResolution: false, requestRenderMode: false,
        contextOptions: { webgl: { preserveDrawingBuffer: true, antialias: false } },
    });
    const scene = widget.scene;
    scene.backgroundColor = Cesium.Color.BLACK;
    scene.fog.enabled = false;
    scene.renderError.addEventListener((s, e) => fail(`renderError: ${e}`));

    const json = await (await fetch(tilesetUrl)).json();
    const tileset = await Cesium.Cesium3DTileset.fromUrl(tilesetUrl, { maximumScreenSpaceError: errorTarget });
    tileset.modelMatrix = Cesium.Transforms.eastNorthUpToFixedFrame(Cesium.Cartesian3.fromDegrees(8.54, 47.37, 400));
    let failed = 0;
    tileset.tileFailed.addEventListener((e) => { failed++; fail(`tileFailed ${e.url}: ${e.message}`); });
    tileset.tileLoad.addEventListener((tile) => result.loadedModels.push(relative(tile.content.url)));
    let visible = new Set();
    tileset.tileVisible.addEventListener((tile) => visible.add(relative(tile.content.url)));
    scene.light = new Cesium.DirectionalLight({ direction: new Cesium.Cartesian3(-0.4, 0.3, -1), intensity: 3 });

    // The camera as 3DTilesRendererJS's page places it, in the tileset's
    // frame (root transform, then the model matrix): looking at the root
    // box's centre from the south-east, 40 degrees up, z up.
    const box = json.root.boundingVolume.box;
    const frame = Cesium.Matrix4.multiply(tileset.modelMatrix,
        json.root.transform ? Cesium.Matrix4.fromColumnMajorArray(json.root.transform) : Cesium.Matrix4.IDENTITY,
        new Cesium.Matrix4());
    const C3 = Cesium.Cartesian3;
    const centre = new C3(box[0], box[1], box[2]);
    const radius = C3.magnitude(C3.add(C3.add(new C3(box[3], box[4], box[5]), new C3(box[6], box[7], box[8]), new C3()),
                                       new C3(box[9], box[10], box[11]), new C3()));
    const dir = C3.normalize(new C3(0.35, -0.55, 0.6), new C3());
    const eye = C3.add(centre, C3.multiplyByScalar(dir, radius * 2.2, new C3()), new C3());
    const point = (p) => Cesium.Matrix4.multiplyByPoint(frame, p, new C3());
    const vector = (v) => C3.normalize(Cesium.Matrix4.multiplyByPointAsVector(frame, v, new C3()), new C3());
    const look = vector(C3.negate(dir, new C3()));
    const right = C3.normalize(C3.cross(look, vector(C3.UNIT_Z), new C3()), new C3());
    widget.camera.frustum.fov = Cesium.Math.toRadians(50 * 800 / 600);
    widget.camera.setView({
        destination: point(eye),
        orientation: { direction: look, up: C3.cross(right, look, new C3()) },
    });

    // Listening before the tileset is drawn: a load can end at its first frame.
    let loaded = false, quiet = 0, frames = 0;
    tileset.allTilesLoaded.addEventListener(() => { loaded = true; });
    scene.primitives.add(tileset);
    await new Promise((resolve) => {
        const post = () => {
            frames++;
            // allTilesLoaded is not raised where nothing was to load (the
            // tileset's geometricError small enough on screen: nothing drawn).
            quiet = (loaded || frames > 100) && tileset.tilesLoaded ? quiet + 1 : 0;
            result.waiting = { frames, loaded, tilesLoaded: tileset.tilesLoaded, visible: [...visible],
                               pending: tileset.statistics.numberOfPendingRequests,
                               processing: tileset.statistics.numberOfTilesProcessing };
            if (quiet >= 10 || frames > 20000) {
                scene.postRender.removeEventListener(post);
                resolve();
            } else {
                visible = new Set();
            }
        };
        scene.postRender.addEventListener(post);
    });
    const stats = {};
    for (const [k, v] of Object.entries(tileset.statistics))
        if (typeof v === 'number')
            stats[k] = v;
    stats.failed = failed;
    Object.assign(result, {
        frames, stats, visibleContent: [...visible].sort(),
        drawnTiles: visible.size, drawnMeshes: visible.size, drawnTriangles: stats.numberOfTrianglesSelected, misplaced: [],
        picture: pictureFigures(scene.canvas, [0, 0, 0], result.paletteHues = paletteFromQuery()),
        done: true,
    });
    widget.useDefaultRenderLoop = false;
}

// The hues of the palette, given by the test (?palette=12,31,...).
function paletteFromQuery() {
    return (params.get('palette') || '').split(',').filter((x) => x !== '').map(Number);
}

main().catch((e) => { fail(`main: ${e && e.stack || e}`); result.done = true; });
