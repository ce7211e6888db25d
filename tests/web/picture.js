// What the pages that test-bake-chromium.sh opens measure of their pictures.

// The hue of an RGB colour in degrees (0 for a grey).
export function hueOf(r, g, b) {
    const max = Math.max(r, g, b), min = Math.min(r, g, b), d = max - min;
    if (d === 0) return 0;
    let h = max === r ? ((g - b) / d) % 6 : max === g ? (b - r) / d + 2 : (r - g) / d + 4;
    h *= 60;
    return h < 0 ? h + 360 : h;
}

// Figures of the picture in a WebGL canvas (drawn with preserveDrawingBuffer):
// the fractions of its pixels unlike the clear colour bg ([r, g, b], 0-255),
// of those coloured (chroma 24 or more), of the coloured within 20 degrees of
// a hue of paletteHues (degrees), and how many of those hues are seen.
export function pictureFigures(canvas, bg, paletteHues) {
    const c2 = document.createElement('canvas');
    c2.width = canvas.width;
    c2.height = canvas.height;
    const ctx = c2.getContext('2d');
    ctx.drawImage(canvas, 0, 0);
    const px = ctx.getImageData(0, 0, c2.width, c2.height).data;
    const hues = [...paletteHues];
    let drawn = 0, coloured = 0, inPalette = 0;
    const seen = new Set();
    for (let i = 0; i < px.length; i += 4) {
        const r = px[i], g = px[i + 1], b = px[i + 2];
        if (Math.abs(r - bg[0]) + Math.abs(g - bg[1]) + Math.abs(b - bg[2]) <= 6)
            continue;
        drawn++;
        if (Math.max(r, g, b) - Math.min(r, g, b) < 24)
            continue;
        coloured++;
        const h = hueOf(r, g, b);
        let best = 360, bestHue = -1;
        for (const p of hues) {
            const d = Math.min(Math.abs(h - p), 360 - Math.abs(h - p));
            if (d < best) { best = d; bestHue = p; }
        }
        if (best <= 20) {
            inPalette++;
            seen.add(bestHue);
        }
    }
    const n = px.length / 4;
    return {
        pixels: n, drawnFraction: drawn / n, colouredFraction: coloured / n,
        inPaletteFraction: coloured ? inPalette / coloured : 0, paletteHuesSeen: seen.size,
    };
}
