/* A tile provider that streams a tileset baked by `tileworld bake` (3D Tiles
 * 1.1, implicit quadtree tiling) back from HTTP or a file (tilesets.h).
 *
 * At creation: tileset.json (its extras.tileworld give the footprint, the
 * rectangle of cells and the bound) and the subtrees down to the cells'
 * level, whose content availability becomes one byte per cell; content()
 * reads it. generate() fetches the cell's .glb on the calling worker
 * (http.c) and reads it: a .glb in the bake's own layout rebuilds the
 * tile as it was finished (tiles3d-glb.c); other glTF is refused. The
 * node translation that places the cell inside the rectangle is dropped,
 * so the tile's geometry is the cell-relative float32 of the file,
 * whatever the rectangle's size.
 *
 * Thread safety: generate() only reads the provider (the fetcher is
 * thread-safe); what a worker still running at destroy uses stays until it
 * returns (a reference count). */
#include <json-c/json.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tiles/tiles-internal.h"
#include "tilesets/http.h"
#include "tilesets/tilesets-private.h"
#include "tileworld/tilesets.h"

/* tileset.json and subtree files are small; a larger one is refused. */
#define MAX_MANIFEST_BYTES (64ull << 20)
/* Levels of the quadtree at most (x and y of the cells fit 32 bits). */
#define MAX_LEVELS 31

struct tw_tiles3d_provider {
    struct tw_tile_provider provider;
    struct tw_tiles3d_settings settings;    /* resolved */
    struct tw_log log;
    struct tw_http *http;
    _Atomic int refs;               /* the owner's, and one per generate() running */
    char *url;                      /* tileset.json's */
    char *base;                     /* the URL up to its last '/' */
    char *content_template;         /* content uri, relative to base */
    char *subtree_template;
    uint32_t subtree_levels;
    uint32_t leaf;                  /* the cells' level */
    struct tw_cell first;           /* the rectangle's corner */
    uint64_t nx, ny;                /* its cells along i and j */
    uint8_t *has_content;           /* nx * ny, row-major along i */
    uint64_t cells_with_content;
    /* The bake's coarser levels (extras.tileworld.levels; their errors in
     * provider.level_error), of which provider.levels line up with the
     * world's blocks: level k's tile (x, y) is block (I0 / 2^k + x,
     * J0 / 2^k + y), there when one of its cells has content. */
    uint32_t levels_baked;
    uint8_t *block_content[TW_PROVIDER_MAX_LEVELS];   /* [k - 1]: row-major, ceil(n / 2^k) */
    _Atomic uint64_t cells_read, blocks_read;
};

void tw_tiles3d_default_settings(struct tw_tiles3d_settings *s)
{
    if (!s)
        return;
    memset(s, 0, sizeof(*s));
    s->cache_max_bytes = 1ull << 30;
    s->connect_timeout_ms = 5000;
    s->timeout_ms = 30000;
    s->retries = 3;
    s->retry_delay_ms = 100;
    s->max_cluster_triangles = 2048;
    tw_gltf_default_settings(&s->gltf);
}

static void resolve(const struct tw_tiles3d_settings *in, struct tw_tiles3d_settings *out)
{
    tw_tiles3d_default_settings(out);
    if (!in)
        return;
    out->cache_dir = in->cache_dir;
    if (in->cache_max_bytes)
        out->cache_max_bytes = in->cache_max_bytes;
    if (in->connect_timeout_ms)
        out->connect_timeout_ms = in->connect_timeout_ms;
    if (in->timeout_ms)
        out->timeout_ms = in->timeout_ms;
    if (in->retries)
        out->retries = in->retries;
    if (in->retry_delay_ms)
        out->retry_delay_ms = in->retry_delay_ms;
    if (in->max_cluster_triangles)
        out->max_cluster_triangles = in->max_cluster_triangles;
    if (in->gltf.max_file_bytes)
        out->gltf.max_file_bytes = in->gltf.max_file_bytes;
    if (in->gltf.max_triangles)
        out->gltf.max_triangles = in->gltf.max_triangles;
}

static void release(struct tw_tiles3d_provider *p)
{
    if (atomic_fetch_sub(&p->refs, 1) != 1)
        return;
    tw_http_destroy(p->http);
    free(p->url);
    free(p->base);
    free(p->content_template);
    free(p->subtree_template);
    free(p->has_content);
    for (uint32_t k = 0; k < TW_PROVIDER_MAX_LEVELS; k++)
        free(p->block_content[k]);
    free(p);
}

/* base + template with {level}, {x} and {y} replaced; NULL when out of
 * memory. */
static char *expand(const struct tw_tiles3d_provider *p, const char *template, uint32_t level,
                    uint64_t x, uint64_t y)
{
    const size_t size = strlen(p->base) + strlen(template) + 3 * 24 + 1;
    char *out = malloc(size);
    if (!out)
        return NULL;
    size_t used = (size_t)snprintf(out, size, "%s", p->base);
    for (const char *s = template; *s;) {
        const char *key = NULL;
        unsigned long long v = 0;
        if (strncmp(s, "{level}", 7) == 0)
            key = "{level}", v = level;
        else if (strncmp(s, "{x}", 3) == 0)
            key = "{x}", v = x;
        else if (strncmp(s, "{y}", 3) == 0)
            key = "{y}", v = y;
        if (key) {
            used += (size_t)snprintf(out + used, size - used, "%llu", v);
            s += strlen(key);
        } else {
            out[used++] = *s++;
            out[used] = '\0';
        }
    }
    return out;
}

/* ---- subtrees ---------------------------------------------------------------------- */

static uint64_t get_le(const uint8_t *b, int n)
{
    uint64_t v = 0;
    for (int k = n - 1; k >= 0; k--)
        v = v << 8 | b[k];
    return v;
}

uint64_t tw_tiles3d_tiles_below(uint32_t levels)
{
    return ((1ull << (2 * levels)) - 1) / 3;
}

uint64_t tw_tiles3d_morton(uint32_t x, uint32_t y)
{
    uint64_t m = 0;
    for (int b = 0; b < 32; b++)
        m |= (uint64_t)((x >> b) & 1u) << (2 * b) | (uint64_t)((y >> b) & 1u) << (2 * b + 1);
    return m;
}

/* An availability of a subtree: a constant, or bits of the binary chunk. */
struct availability {
    int constant;               /* 0 or 1 when bits is NULL */
    const uint8_t *bits;
    uint64_t bit_count;
};

static bool available(const struct availability *a, uint64_t bit)
{
    if (!a->bits)
        return a->constant != 0;
    return bit < a->bit_count && (a->bits[bit / 8] >> (bit % 8)) & 1u;
}

static int parse_availability(json_object *o, json_object *views, const uint8_t *bin,
                              uint64_t bin_size, struct availability *out, const char **why)
{
    json_object *v = NULL;
    memset(out, 0, sizeof(*out));
    if (!o || !json_object_is_type(o, json_type_object)) {
        *why = "an availability is not an object";
        return TW_ERR_FORMAT;
    }
    if (json_object_object_get_ex(o, "constant", &v)) {
        out->constant = json_object_get_int(v) != 0;
        return TW_OK;
    }
    if (!json_object_object_get_ex(o, "bitstream", &v) || !views) {
        *why = "an availability has neither constant nor bitstream";
        return TW_ERR_FORMAT;
    }
    json_object *view = json_object_array_get_idx(views, (size_t)json_object_get_int(v));
    json_object *off = NULL, *len = NULL, *buf = NULL;
    if (!view || !json_object_object_get_ex(view, "byteLength", &len) ||
        (json_object_object_get_ex(view, "buffer", &buf) && json_object_get_int(buf) != 0)) {
        *why = "a bitstream's buffer view is missing or names another buffer than the "
               "subtree's own";
        return TW_ERR_FORMAT;
    }
    const int64_t o64 = json_object_object_get_ex(view, "byteOffset", &off)
                            ? json_object_get_int64(off)
                            : 0;
    const int64_t l64 = json_object_get_int64(len);
    if (o64 < 0 || l64 < 0 || (uint64_t)o64 > bin_size || (uint64_t)l64 > bin_size - (uint64_t)o64) {
        *why = "a bitstream lies outside the subtree's binary chunk";
        return TW_ERR_FORMAT;
    }
    out->bits = bin + o64;
    out->bit_count = 8 * (uint64_t)l64;
    return TW_OK;
}

static int fetch(struct tw_tiles3d_provider *p, const char *url, uint64_t max_bytes,
                 void **body, size_t *size)
{
    char err[512];
    long status = 0;
    bool missing = false;
    const int rc = tw_http_get(p->http, url, max_bytes, body, size, &status, &missing, err,
                               sizeof(err));
    if (rc) {
        char shown[600];
        tw_log_printf(&p->log, TW_LOG_ERROR, "3D Tiles: GET %s: %s",
                      tw_log_escape(url, shown, sizeof(shown)), err);
    }
    return rc;
}

/* Reads the subtree whose root is tile (root, sx, sy) and marks the cells
 * with content; walks into its child subtrees when the cells lie below. */
static int load_subtree(struct tw_tiles3d_provider *p, uint32_t root, uint64_t sx, uint64_t sy,
                        uint64_t *fetched)
{
    char *url = expand(p, p->subtree_template, root, sx, sy);
    if (!url)
        return TW_ERR_NOMEM;
    void *data = NULL;
    size_t size = 0;
    int rc = fetch(p, url, MAX_MANIFEST_BYTES, &data, &size);
    json_object *doc = NULL;
    const char *why = NULL;
    if (rc)
        goto out;
    (*fetched)++;
    const uint8_t *b = data;
    if (size < 24 || memcmp(b, "subt", 4) != 0 || get_le(b + 4, 4) != 1) {
        why = "not a subtree file (magic \"subt\", version 1)";
        goto bad;
    }
    const uint64_t json_len = get_le(b + 8, 8), bin_len = get_le(b + 16, 8);
    if (json_len > size - 24 || bin_len > size - 24 - json_len) {
        why = "its chunks are longer than the file";
        goto bad;
    }
    json_tokener *tok = json_tokener_new();
    if (!tok) {
        rc = TW_ERR_NOMEM;
        goto out;
    }
    doc = json_tokener_parse_ex(tok, (const char *)b + 24, (int)json_len);
    json_tokener_free(tok);
    const uint8_t *bin = b + 24 + json_len;
    json_object *views = NULL, *tiles_o = NULL, *content_o = NULL, *children_o = NULL;
    json_object *buffers = NULL;
    if (!doc || !json_object_is_type(doc, json_type_object)) {
        why = "its JSON chunk is not a JSON object";
        goto bad;
    }
    if (json_object_object_get_ex(doc, "buffers", &buffers)) {
        json_object *b0 = json_object_array_get_idx(buffers, 0), *uri = NULL;
        if (b0 && json_object_object_get_ex(b0, "uri", &uri)) {
            why = "its bitstreams are in an external buffer (not supported: tileworld bake "
                  "writes them into the subtree)";
            goto bad;
        }
    }
    json_object_object_get_ex(doc, "bufferViews", &views);
    json_object_object_get_ex(doc, "tileAvailability", &tiles_o);
    json_object_object_get_ex(doc, "childSubtreeAvailability", &children_o);
    if (json_object_object_get_ex(doc, "contentAvailability", &content_o) &&
        json_object_is_type(content_o, json_type_array))
        content_o = json_object_array_get_idx(content_o, 0);
    struct availability tiles, content, children;
    if ((rc = parse_availability(tiles_o, views, bin, bin_len, &tiles, &why)) ||
        (rc = parse_availability(children_o, views, bin, bin_len, &children, &why)))
        goto bad;
    if (!content_o) {
        content.constant = 0;
        content.bits = NULL;
    } else if ((rc = parse_availability(content_o, views, bin, bin_len, &content, &why))) {
        goto bad;
    }
    const uint32_t s = p->subtree_levels;
    if (p->leaf < root + s) {
        /* The cells are level l of this subtree. */
        const uint32_t l = p->leaf - root;
        const uint64_t side = 1ull << l;
        for (uint64_t ly = 0; ly < side; ly++) {
            const uint64_t y = (sy << l) + ly;
            if (y >= p->ny)
                break;
            for (uint64_t lx = 0; lx < side; lx++) {
                const uint64_t x = (sx << l) + lx;
                if (x >= p->nx)
                    break;
                const uint64_t bit = tw_tiles3d_tiles_below(l) + tw_tiles3d_morton((uint32_t)lx, (uint32_t)ly);
                if (available(&tiles, bit) && available(&content, bit)) {
                    p->has_content[y * p->nx + x] = 1;
                    p->cells_with_content++;
                }
            }
        }
    } else {
        const uint64_t side = 1ull << s;
        for (uint64_t ly = 0; ly < side && !rc; ly++)
            for (uint64_t lx = 0; lx < side && !rc; lx++) {
                const uint64_t cx = (sx << s) + lx, cy = (sy << s) + ly;
                /* Children beyond the rectangle hold no cell of it. */
                const uint32_t up = p->leaf - (root + s);
                if ((cx << up) >= p->nx || (cy << up) >= p->ny)
                    continue;
                if (available(&children, tw_tiles3d_morton((uint32_t)lx, (uint32_t)ly)))
                    rc = load_subtree(p, root + s, cx, cy, fetched);
            }
    }
    goto out;
bad:
    if (!rc)
        rc = TW_ERR_FORMAT;
    {
        char shown[600];
        tw_log_printf(&p->log, TW_LOG_ERROR, "3D Tiles: %s: %s",
                      tw_log_escape(url, shown, sizeof(shown)), why);
    }
out:
    json_object_put(doc);
    free(data);
    free(url);
    return rc;
}

/* ---- tileset.json ---------------------------------------------------------------------- */

static bool get_path(json_object *o, const char *const *keys, json_object **out)
{
    for (; *keys; keys++)
        if (!o || !json_object_is_type(o, json_type_object) ||
            !json_object_object_get_ex(o, *keys, &o))
            return false;
    *out = o;
    return true;
}

static bool get_doubles(json_object *a, double *v, size_t n)
{
    if (!a || !json_object_is_type(a, json_type_array) || json_object_array_length(a) != n)
        return false;
    for (size_t k = 0; k < n; k++) {
        json_object *e = json_object_array_get_idx(a, k);
        if (!json_object_is_type(e, json_type_double) && !json_object_is_type(e, json_type_int))
            return false;
        v[k] = json_object_get_double(e);
        if (!(v[k] == v[k]) || v[k] > 1e30 || v[k] < -1e30)
            return false;
    }
    return true;
}

static int parse_tileset(struct tw_tiles3d_provider *p, const char *text, size_t size)
{
    const char *why = NULL;
    json_tokener *tok = json_tokener_new();
    if (!tok)
        return TW_ERR_NOMEM;
    json_object *doc = json_tokener_parse_ex(tok, text, (int)size);
    json_tokener_free(tok);
    json_object *o = NULL;
    double fp[2], cells[4], bmin[3], bmax[3];
    if (!doc || !json_object_is_type(doc, json_type_object)) {
        why = "not a JSON object";
        goto bad;
    }
    if (!get_path(doc, (const char *const[]){"extras", "tileworld", NULL}, &o)) {
        why = "no extras.tileworld: not a tileset written by tileworld bake (the footprint "
              "and the rectangle of cells are not known)";
        goto bad;
    }
    json_object *tw = o, *fp_o = NULL, *cells_o = NULL, *bmin_o = NULL, *bmax_o = NULL;
    json_object_object_get_ex(tw, "footprint", &fp_o);
    json_object_object_get_ex(tw, "cells", &cells_o);
    get_path(tw, (const char *const[]){"bound", "min", NULL}, &bmin_o);
    get_path(tw, (const char *const[]){"bound", "max", NULL}, &bmax_o);
    if (!get_doubles(fp_o, fp, 2) || !(fp[0] > 0.0 && fp[1] > 0.0 && fp[0] <= 1e5 && fp[1] <= 1e5)) {
        why = "extras.tileworld.footprint is not two sizes in metres";
        goto bad;
    }
    if (!get_doubles(cells_o, cells, 4) || cells[2] < cells[0] || cells[3] < cells[1] ||
        cells[0] < -4.6e18 || cells[3] > 4.6e18) {
        why = "extras.tileworld.cells is not I0, J0, I1, J1 with I1 >= I0, J1 >= J0";
        goto bad;
    }
    if (!get_doubles(bmin_o, bmin, 3) || !get_doubles(bmax_o, bmax, 3)) {
        why = "extras.tileworld.bound is not {min: [x, y, z], max: [x, y, z]}";
        goto bad;
    }
    json_object *implicit = NULL, *v = NULL;
    if (!get_path(doc, (const char *const[]){"root", "implicitTiling", NULL}, &implicit) ||
        !json_object_object_get_ex(implicit, "subdivisionScheme", &v) ||
        strcmp(json_object_get_string(v), "QUADTREE") != 0) {
        why = "root.implicitTiling is not a QUADTREE";
        goto bad;
    }
    json_object *levels_o = NULL, *available_o = NULL, *subtree_uri = NULL, *content_uri = NULL;
    json_object_object_get_ex(implicit, "subtreeLevels", &levels_o);
    json_object_object_get_ex(implicit, "availableLevels", &available_o);
    get_path(implicit, (const char *const[]){"subtrees", "uri", NULL}, &subtree_uri);
    get_path(doc, (const char *const[]){"root", "content", "uri", NULL}, &content_uri);
    const int64_t sl = levels_o ? json_object_get_int64(levels_o) : 0;
    const int64_t al = available_o ? json_object_get_int64(available_o) : 0;
    if (sl < 1 || sl > MAX_LEVELS || al < 1 || al > MAX_LEVELS + 1 || !subtree_uri ||
        !content_uri) {
        why = "root.implicitTiling needs subtreeLevels and availableLevels in 1..31 and "
              "subtrees.uri, and root.content.uri";
        goto bad;
    }
    p->subtree_levels = (uint32_t)sl;
    p->leaf = (uint32_t)(al - 1);
    p->first.i = (int64_t)cells[0];
    p->first.j = (int64_t)cells[1];
    p->nx = (uint64_t)((int64_t)cells[2] - (int64_t)cells[0]) + 1;
    p->ny = (uint64_t)((int64_t)cells[3] - (int64_t)cells[1]) + 1;
    if (p->nx > (1ull << p->leaf) || p->ny > (1ull << p->leaf) || p->nx * p->ny > (1ull << 32)) {
        why = "extras.tileworld.cells is larger than the quadtree's finest level";
        goto bad;
    }
    p->subtree_template = strdup(json_object_get_string(subtree_uri));
    p->content_template = strdup(json_object_get_string(content_uri));
    p->has_content = calloc(p->nx * p->ny, 1);
    if (!p->subtree_template || !p->content_template || !p->has_content) {
        json_object_put(doc);
        return TW_ERR_NOMEM;
    }
    json_object *levels_list = NULL;
    if (json_object_object_get_ex(tw, "levels", &levels_list)) {
        const size_t n = json_object_is_type(levels_list, json_type_array)
                             ? json_object_array_length(levels_list)
                             : SIZE_MAX;
        if (n > TW_PROVIDER_MAX_LEVELS || n > p->leaf) {
            why = "extras.tileworld.levels is not a list of at most 11 levels above the cells";
            goto bad;
        }
        for (size_t k = 0; k < n; k++) {
            json_object *lv = json_object_array_get_idx(levels_list, k), *c = NULL, *e = NULL;
            double err = -1.0;
            if (!json_object_is_type(lv, json_type_object) ||
                !json_object_object_get_ex(lv, "cells", &c) ||
                json_object_get_int64(c) != (int64_t)1 << (k + 1) ||
                !json_object_object_get_ex(lv, "geometricError", &e) ||
                !(json_object_is_type(e, json_type_double) ||
                  json_object_is_type(e, json_type_int)) ||
                !((err = json_object_get_double(e)) >= 0.0 && err <= 1e9)) {
                why = "extras.tileworld.levels[k] is not {cells: 2^(k+1), geometricError: "
                      "metres}";
                goto bad;
            }
            p->provider.level_error[k] = (float)err;
        }
        p->levels_baked = (uint32_t)n;
    }
    struct tw_tile_provider *tp = &p->provider;
    tp->footprint[0] = (float)fp[0];
    tp->footprint[1] = (float)fp[1];
    for (int a = 0; a < 3; a++) {
        tp->bound.min[a] = (float)bmin[a];
        tp->bound.max[a] = (float)bmax[a];
    }
    json_object_put(doc);
    return TW_OK;
bad:
    {
        char shown[600];
        tw_log_printf(&p->log, TW_LOG_ERROR, "3D Tiles: %s: %s",
                      tw_log_escape(p->url, shown, sizeof(shown)), why);
    }
    json_object_put(doc);
    return TW_ERR_FORMAT;
}

/* ---- the provider's calls ---------------------------------------------------------------- */

static uint32_t tiles3d_content(void *user, struct tw_cell cell)
{
    const struct tw_tiles3d_provider *p = user;
    /* Unsigned differences: a cell before the corner wraps far beyond. */
    const uint64_t x = (uint64_t)cell.i - (uint64_t)p->first.i;
    const uint64_t y = (uint64_t)cell.j - (uint64_t)p->first.j;
    if (x >= p->nx || y >= p->ny)
        return TW_TILE_EMPTY;
    return p->has_content[y * p->nx + x] ? TW_TILE_OWN : TW_TILE_EMPTY;
}

/* Fetches the quadtree's tile (level, x, y), the cells' level or a coarser
 * one, and reads it into ts as its prototype name. */
static int fetch_tile(struct tw_tiles3d_provider *p, uint32_t level, uint64_t x, uint64_t y,
                      const char *name, struct tw_tileset *ts)
{
    char *url = NULL;
    void *data = NULL;
    size_t size = 0;
    char err[512], shown[600];
    long status = 0;
    bool missing = false;
    int rc;
    url = expand(p, p->content_template, level, x, y);
    if (!url) {
        rc = tw_tileset_fail(ts, TW_ERR_NOMEM, "out of memory");
        goto out;
    }
    tw_log_escape(url, shown, sizeof(shown));
    rc = tw_http_get(p->http, url, p->settings.gltf.max_file_bytes, &data, &size, &status,
                     &missing, err, sizeof(err));
    if (rc) {
        rc = tw_tileset_fail(ts, rc, "GET %s: %s%s", shown, err,
                             missing ? " (the subtree says the tile is there)" : "");
        goto out;
    }
    const int proto = tw_tileset_add_prototype(ts, name, 1.0f);
    if (proto < 0) {
        rc = tw_tileset_fail(ts, proto, "%s: cannot make the tile: %s", shown,
                             tw_error_to_str(proto));
        goto out;
    }
    /* The bake's own layout: the tile as it was finished, rebuilt exactly;
     * its small instances are merged already, so nothing is merged again
     * (tw_tileset_finish() then only splits the meshes into the same parts). */
    rc = tw_tiles3d_glb_read(data, size, ts, (uint32_t)proto, NULL, NULL, err, sizeof(err));
    if (rc)
        rc = tw_tileset_fail(ts, rc, "%s: %s", shown, err);
    else
        ts->merge_triangles = 1;
out:
    free(data);
    free(url);
    return rc;
}

static int tiles3d_generate(void *user, struct tw_cell cell, struct tw_tileset *ts)
{
    struct tw_tiles3d_provider *p = user;
    atomic_fetch_add(&p->refs, 1);
    const uint64_t x = (uint64_t)cell.i - (uint64_t)p->first.i;
    const uint64_t y = (uint64_t)cell.j - (uint64_t)p->first.j;
    int rc = TW_GENERATE_EMPTY;
    if (x < p->nx && y < p->ny && p->has_content[y * p->nx + x]) {
        char name[48];
        snprintf(name, sizeof(name), "%lld,%lld", (long long)cell.i, (long long)cell.j);
        rc = fetch_tile(p, p->leaf, x, y, name, ts);
        if (rc == TW_OK)
            atomic_fetch_add(&p->cells_read, 1);
    }
    release(p);
    return rc;
}

/* The tiles of level k's blocks along i and j. */
static void level_size(const struct tw_tiles3d_provider *p, uint32_t k, uint64_t *w, uint64_t *h)
{
    *w = (p->nx + (1ull << k) - 1) >> k;
    *h = (p->ny + (1ull << k) - 1) >> k;
}

static int tiles3d_generate_level(void *user, uint32_t k, struct tw_cell block,
                                  struct tw_tileset *ts)
{
    struct tw_tiles3d_provider *p = user;
    if (k < 1 || k > p->provider.levels)
        return tw_tileset_fail(ts, TW_ERR_INVALID, "level %u: the tileset has levels 1 to %u",
                               k, p->provider.levels);
    atomic_fetch_add(&p->refs, 1);
    /* The corner lines up with the level's blocks (levels_offered). */
    const uint64_t x = (uint64_t)block.i - (uint64_t)(p->first.i >> k);
    const uint64_t y = (uint64_t)block.j - (uint64_t)(p->first.j >> k);
    uint64_t w, h;
    level_size(p, k, &w, &h);
    int rc = TW_GENERATE_EMPTY;
    if (x < w && y < h && p->block_content[k - 1][y * w + x]) {
        char name[64];
        snprintf(name, sizeof(name), "block %ux%u %lld,%lld", 1u << k, 1u << k,
                 (long long)block.i, (long long)block.j);
        rc = fetch_tile(p, p->leaf - k, x, y, name, ts);
        if (rc == TW_OK)
            atomic_fetch_add(&p->blocks_read, 1);
    }
    release(p);
    return rc;
}

/* The baked levels that the world's blocks can use: level k's blocks start
 * at multiples of 2^k cells and the bake's at its corner, so the corner
 * must be one. A block is there when one of its cells is: the bake writes
 * a block wherever a child has triangles. */
static int levels_offered(struct tw_tiles3d_provider *p)
{
    uint32_t n = 0;
    while (n < p->levels_baked && ((uint64_t)p->first.i & ((2ull << n) - 1)) == 0 &&
           ((uint64_t)p->first.j & ((2ull << n) - 1)) == 0)
        n++;
    for (uint32_t k = 1; k <= n; k++) {
        uint64_t w, h, cw, ch;
        level_size(p, k, &w, &h);
        level_size(p, k - 1, &cw, &ch);
        const uint8_t *below = k == 1 ? p->has_content : p->block_content[k - 2];
        uint8_t *q = calloc(w * h, 1);
        if (!q)
            return TW_ERR_NOMEM;
        for (uint64_t y = 0; y < ch; y++)
            for (uint64_t x = 0; x < cw; x++)
                if (below[y * cw + x])
                    q[(y >> 1) * w + (x >> 1)] = 1;
        p->block_content[k - 1] = q;
    }
    p->provider.levels = n;
    return TW_OK;
}


/* ---- the public calls -------------------------------------------------------------------- */

int tw_tiles3d_provider_create(const char *url, const struct tw_tiles3d_settings *settings,
                               const struct tw_log *log, struct tw_tiles3d_provider **out)
{
    if (!out || !url) {
        tw_log_printf(log, TW_LOG_ERROR, "3D Tiles: %s is NULL (caller's bug)",
                      out ? "the URL" : "out");
        return TW_ERR_INVALID;
    }
    *out = NULL;
    char shown[600];
    tw_log_escape(url, shown, sizeof(shown));
    if (strncmp(url, "http://", 7) != 0 && strncmp(url, "https://", 8) != 0 &&
        strncmp(url, "file://", 7) != 0) {
        tw_log_printf(log, TW_LOG_ERROR, "3D Tiles: %s: not an http://, https:// or file:// URL",
                      shown);
        return TW_ERR_INVALID;
    }
    struct tw_tiles3d_provider *p = calloc(1, sizeof(*p));
    if (!p) {
        tw_log_printf(log, TW_LOG_ERROR, "3D Tiles: out of memory");
        return TW_ERR_NOMEM;
    }
    atomic_init(&p->refs, 1);
    if (log)
        p->log = *log;
    resolve(settings, &p->settings);
    p->url = strdup(url);
    const char *query = strchr(url, '?');
    size_t end = query ? (size_t)(query - url) : strlen(url);
    while (end > 0 && url[end - 1] != '/')
        end--;
    p->base = strndup(url, end);
    int rc = TW_ERR_NOMEM;
    if (!p->url || !p->base) {
        tw_log_printf(log, TW_LOG_ERROR, "3D Tiles: out of memory");
        goto fail;
    }
    char err[512];
    rc = tw_http_create(&p->settings, &p->http, err, sizeof(err));
    if (rc) {
        tw_log_printf(log, TW_LOG_ERROR, "3D Tiles: %s: %s", shown, err);
        goto fail;
    }
    p->settings.cache_dir = NULL;   /* the fetcher holds its copy */
    void *text = NULL;
    size_t size = 0;
    if ((rc = fetch(p, url, MAX_MANIFEST_BYTES, &text, &size)))
        goto fail;
    rc = parse_tileset(p, text, size);
    free(text);
    if (rc)
        goto fail;
    uint64_t subtrees = 0;
    if ((rc = load_subtree(p, 0, 0, 0, &subtrees)))
        goto fail;
    if ((rc = levels_offered(p))) {
        tw_log_printf(log, TW_LOG_ERROR, "3D Tiles: out of memory");
        goto fail;
    }
    struct tw_tile_provider *tp = &p->provider;
    tp->name = p->url;
    tp->shared = NULL;
    tp->content = tiles3d_content;
    tp->generate = tiles3d_generate;
    tp->user = p;
    tp->max_cluster_triangles = p->settings.max_cluster_triangles;
    tp->generate_level = tp->levels ? tiles3d_generate_level : NULL;
    if (tp->levels < p->levels_baked)
        tw_log_printf(log, TW_LOG_WARN,
                      "3D Tiles: %s: %u of its %u coarser levels are used: its corner %lld,%lld "
                      "is not a multiple of %u cells, where the world's blocks of level %u start",
                      shown, tp->levels, p->levels_baked, (long long)p->first.i,
                      (long long)p->first.j, 2u << tp->levels, tp->levels + 1);

    tw_log_printf(log, TW_LOG_INFO,
                  "3D Tiles: %s: cells %lld,%lld to %lld,%lld, %llu with content, %u levels, "
                  "%llu subtree files", shown, (long long)p->first.i, (long long)p->first.j,
                  (long long)(p->first.i + (int64_t)p->nx - 1),
                  (long long)(p->first.j + (int64_t)p->ny - 1),
                  (unsigned long long)p->cells_with_content, p->leaf + 1,
                  (unsigned long long)subtrees);
    *out = p;
    return TW_OK;
fail:
    release(p);
    return rc;
}

const struct tw_tile_provider *tw_tiles3d_provider_get(const struct tw_tiles3d_provider *p)
{
    return p ? &p->provider : NULL;
}

void tw_tiles3d_provider_stats(const struct tw_tiles3d_provider *p, struct tw_tiles3d_stats *out)
{
    if (!out)
        return;
    memset(out, 0, sizeof(*out));
    if (p && p->http)
        tw_http_stats(p->http, out);
    if (p) {
        out->cells = atomic_load(&p->cells_read);
        out->blocks = atomic_load(&p->blocks_read);
    }
}

void tw_tiles3d_provider_destroy(struct tw_tiles3d_provider *p)
{
    if (!p)
        return;
    if (p->http)
        tw_http_cancel(p->http);
    release(p);
}
