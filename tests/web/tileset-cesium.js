// Draws the tileset named by ?tileset= with CesiumJS (no globe, no imagery,
// nothing from outside) and leaves in window.result what
// test-bake-chromium.sh checks: the tiles drawn (content URIs), the
// tileset's statistics, the errors, and figures of the picture.
//
// ?tileset=URL    tileset.json
// ?error=PX       the tileset's maximumScreenSpaceError
// The tileset's frame is put east-north-up at 8.54 E, 47.37 N (the README's
// way to put a bake on the globe); the camera frames its root's bounding
// sphere.
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

    const tileset = await Cesium.Cesium3DTileset.fromUrl(tilesetUrl, { maximumScreenSpaceError: errorTarget });
    tileset.modelMatrix = Cesium.Transforms.eastNorthUpToFixedFrame(Cesium.Cartesian3.fromDegrees(8.54, 47.37, 400));
    scene.primitives.add(tileset);
    let failed = 0;
    tileset.tileFailed.addEventListener((e) => { failed++; fail(`tileFailed ${e.url}: ${e.message}`); });
    tileset.tileLoad.addEventListener((tile) => result.loadedModels.push(relative(tile.content.url)));
    let visible = new Set();
    tileset.tileVisible.addEventListener((tile) => visible.add(relative(tile.content.url)));
    scene.light = new Cesium.DirectionalLight({ direction: new Cesium.Cartesian3(-0.4, 0.3, -1), intensity: 3 });

    const sphere = tileset.boundingSphere;
    widget.camera.viewBoundingSphere(sphere,
        new Cesium.HeadingPitchRange(Cesium.Math.toRadians(-30), Cesium.Math.toRadians(-40), sphere.radius * 2.2));
    widget.camera.lookAtTransform(Cesium.Matrix4.IDENTITY);

    let loaded = false, quiet = 0, frames = 0;
    tileset.allTilesLoaded.addEventListener(() => { loaded = true; });
    await new Promise((resolve) => {
        const post = () => {
            frames++;
            quiet = loaded && tileset.tilesLoaded ? quiet + 1 : 0;
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
        drawnMeshes: visible.size, drawnTriangles: stats.numberOfTrianglesSelected, misplaced: [],
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
