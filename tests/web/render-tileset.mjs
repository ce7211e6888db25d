// node render-tileset.mjs TILESET_DIR SCREENSHOT.png [QUERY [PAGE]]
// Serves TILESET_DIR under /tileset/, this folder's page and its
// node_modules on 127.0.0.1 (a port the system picks), opens the page in
// headless Debian Chromium (playwright-core; WebGL through SwiftShader),
// waits for the page's window.result, saves a screenshot of it to
// SCREENSHOT.png and prints one JSON object: the page's result plus the
// console's errors and warnings. QUERY (e.g. "error=0&distance=2") goes to the
// page. PAGE: tileset-3dtr.html (3DTilesRendererJS, the default) or
// tileset-cesium.html (CesiumJS). Exit status 0 when the page finished, 1 otherwise, 77 when
// playwright-core or Chromium is missing.
import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const [tilesetDir, screenshot, query = '', pageName = 'tileset-3dtr.html'] = process.argv.slice(2);
if (!tilesetDir || !screenshot) {
    console.error('usage: node render-tileset.mjs TILESET_DIR SCREENSHOT.png [QUERY [PAGE]]');
    process.exit(2);
}
const chromium_path = process.env.CHROMIUM || '/usr/bin/chromium';
let chromium;
try {
    ({ chromium } = await import('playwright-core'));
} catch (e) {
    console.error(`no playwright-core (npm ci --prefix tests/web): ${e.message}`);
    process.exit(77);
}
if (!fs.existsSync(chromium_path)) {
    console.error(`no ${chromium_path} (apt-get install chromium)`);
    process.exit(77);
}

const types = {
    '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.json': 'application/json',
    '.css': 'text/css', '.png': 'image/png', '.svg': 'image/svg+xml', '.wasm': 'application/wasm',
    '.glb': 'model/gltf-binary', '.subtree': 'application/octet-stream', '.map': 'application/json',
};
const roots = [
    ['/tileset/', path.resolve(tilesetDir)],
    ['/node_modules/', path.join(here, 'node_modules')],
    ['/', here],
];
const requests = [];
const server = http.createServer((req, res) => {
    const url = new URL(req.url, 'http://localhost');
    const pathname = decodeURIComponent(url.pathname);
    for (const [prefix, dir] of roots) {
        if (!pathname.startsWith(prefix))
            continue;
        const file = path.join(dir, pathname.slice(prefix.length));
        if (!file.startsWith(dir)) break;
        fs.readFile(file, (err, data) => {
            requests.push(`${err ? 404 : 200} ${pathname}`);
            if (err) {
                res.writeHead(404).end();
                return;
            }
            res.writeHead(200, { 'Content-Type': types[path.extname(file)] || 'application/octet-stream' });
            res.end(data);
        });
        return;
    }
    res.writeHead(404).end();
});
await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));
const base = `http://127.0.0.1:${server.address().port}`;

const console_messages = [];
let browser;
let status = 1;
try {
    browser = await chromium.launch({
        executablePath: chromium_path,
        headless: true,
        args: [
            '--no-sandbox', '--headless=new', '--no-first-run', '--disable-quic', '--disable-sync',
            '--disable-background-networking', '--disable-component-update',
            '--use-gl=angle', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
            '--ignore-gpu-blocklist', '--enable-webgl',
        ],
    });
    const page = await browser.newPage({ viewport: { width: 800, height: 600 } });
    page.on('console', (m) => {
        if (m.type() === 'error' || m.type() === 'warning')
            console_messages.push(`${m.type()}: ${m.text()}`);
    });
    page.on('pageerror', (e) => console_messages.push(`pageerror: ${e.message}`));
    page.on('requestfailed', (r) => console_messages.push(`requestfailed: ${r.url()} ${r.failure()?.errorText}`));
    const q = `tileset=${encodeURIComponent('/tileset/tileset.json')}${query ? '&' + query : ''}`;
    await page.goto(`${base}/${pageName}?${q}`);
    try {
        await page.waitForFunction(() => window.result && window.result.done, null,
                                   { timeout: Number(process.env.TW_PAGE_TIMEOUT_MS || 240000), polling: 500 });
    } catch (e) {
        // What the page had when it gave up.
        console_messages.push(`page state: ${await page.evaluate(() => JSON.stringify(window.result))}`);
        throw e;
    }
    const result = await page.evaluate(() => window.result);
    await page.screenshot({ path: screenshot });
    result.console = console_messages;
    result.requests = requests;
    result.renderer = await page.evaluate(() => {
        const gl = document.createElement('canvas').getContext('webgl2');
        const ext = gl && gl.getExtension('WEBGL_debug_renderer_info');
        return gl ? (ext ? gl.getParameter(ext.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER)) : 'no webgl2';
    });
    console.log(JSON.stringify(result, null, 1));
    status = 0;
} catch (e) {
    console.error(`render-tileset: ${e.stack || e}`);
    console.error(console_messages.join('\n'));
} finally {
    if (browser)
        await browser.close();
    server.close();
}
process.exit(status);
