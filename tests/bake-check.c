/*
 * bake-check DIR [partial]: checks a folder that `tileworld bake` wrote, against the
 * library that made it (test-bake.sh runs it):
 *   - tileset.json parses, is 3D Tiles 1.1 with implicit tiling: QUADTREE,
 *     subtreeLevels, availableLevels = the finest level + 1, the subtree and
 *     content templates, a box, a transform that places cell (I0, J0);
 *   - every cell of the rectangle (bake.json) that shows something has its
 *     .glb, which the project's own importer reads (tw_gltf_import), with
 *     the triangles of the cell's prototype (or generated tile), its nodes'
 *     meshes summed, inside the cell's footprint once placed; read back as
 *     the 3D Tiles provider reads it (tw_tiles3d_glb_read, then
 *     tw_tileset_finish), the very tile that was baked, bit for bit; an
 *     empty cell has none;
 *   - every coarser tile with content: read back, inside its block, with
 *     fewer triangles than its children;
 *   - the root subtree's header and JSON, its tile, content and child
 *     availability bits against the files on disk.
 */
#include <json-c/json.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "tests/check.h"
#include "tiles/tiles-internal.h"
#include "tileworld/tiles.h"
#include "tileworld/tilesets.h"
#include "tilesets/tilesets-private.h"

static json_object *get(json_object *o, const char *key)
{
    json_object *v = NULL;
    return o && json_object_object_get_ex(o, key, &v) ? v : NULL;
}

static bool exists(const char *path)
{
    struct stat st;
    return stat(path, &st) == 0;
}

static uint8_t *read_all(const char *path, size_t *size)
{
    FILE *f = fopen(path, "rb");
    if (!f)
        return NULL;
    fseek(f, 0, SEEK_END);
    const long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    uint8_t *d = malloc(n > 0 ? (size_t)n : 1);
    if (d && fread(d, 1, (size_t)n, f) != (size_t)n) {
        free(d);
        d = NULL;
    }
    fclose(f);
    *size = (size_t)n;
    return d;
}

static uint64_t u64(const uint8_t *p)
{
    uint64_t v = 0;
    for (int k = 7; k >= 0; k--)
        v = v << 8 | p[k];
    return v;
}

static uint64_t morton(uint32_t x, uint32_t y)
{
    uint64_t m = 0;
    for (int b = 0; b < 32; b++)
        m |= (uint64_t)((x >> b) & 1u) << (2 * b) | (uint64_t)((y >> b) & 1u) << (2 * b + 1);
    return m;
}

/* Bit b of an availability: a constant or a bitstream of the subtree. */
static int bit(json_object *avail, json_object *views, const uint8_t *bin, uint64_t b)
{
    json_object *c = get(avail, "constant");
    if (c)
        return json_object_get_int(c);
    json_object *v = json_object_array_get_idx(views, json_object_get_int(get(avail, "bitstream")));
    const uint64_t off = (uint64_t)json_object_get_int64(get(v, "byteOffset"));
    return (bin[off + b / 8] >> (b % 8)) & 1;
}

/* Whether the file at path, read back as the 3D Tiles provider reads it
 * (tw_tiles3d_glb_read, nothing merged again, finished with the same
 * cluster size), gives prototype p of ts bit for bit: the same clusters in
 * the same order, each with the same transform, material, box, and the
 * same triangles (positions, normals, colours) in the same order. */
static bool same_tile(const char *path, const struct tw_tileset *ts, uint32_t p)
{
    size_t size = 0;
    uint8_t *data = read_all(path, &size);
    struct tw_tileset *back = NULL;
    char why[512] = "";
    bool same = data && tw_tileset_create("back", ts->footprint[0], ts->footprint[1], &back) == 0;
    const int proto = same ? tw_tileset_add_prototype(back, "back", 1.0f) : -1;
    same = same && proto == 0 && tw_tiles3d_glb_read(data, size, back, 0, NULL, NULL, why,
                                                     sizeof(why)) == TW_OK;
    if (same)
        back->merge_triangles = 1;
    same = same && tw_tileset_finish(back, ts->max_cluster_triangles) == TW_OK;
    const struct tw_prototype *a = &ts->prototypes[p], *b = same ? &back->prototypes[0] : NULL;
    same = same && a->cluster_count == b->cluster_count && a->triangle_count == b->triangle_count;
    for (uint32_t c = 0; same && c < a->cluster_count; c++) {
        const struct tw_cluster *ca = &a->clusters[c], *cb = &b->clusters[c];
        const struct tw_instance *ia = &a->instances[ca->instance];
        const struct tw_instance *ib = &b->instances[cb->instance];
        const struct tw_mesh_part *pa = &ts->parts[ca->part], *pb = &back->parts[cb->part];
        const struct tw_mesh *ma = &ts->meshes[pa->mesh], *mb = &back->meshes[pb->mesh];
        same = ca->triangle_count == cb->triangle_count &&
               memcmp(&ca->box, &cb->box, sizeof(ca->box)) == 0 &&
               memcmp(ia->transform, ib->transform, sizeof(ia->transform)) == 0 &&
               memcmp(ts->materials[ia->material].base_color,
                      back->materials[ib->material].base_color, 16) == 0 &&
               !ma->colors == !mb->colors;
        for (uint32_t k = 0; same && k < 3 * pa->triangle_count; k++) {
            const uint32_t va = ma->indices[3 * (size_t)pa->first_triangle + k];
            const uint32_t vb = mb->indices[3 * (size_t)pb->first_triangle + k];
            same = memcmp(ma->positions + 3 * (size_t)va, mb->positions + 3 * (size_t)vb, 12) == 0 &&
                   memcmp(ma->normals + 3 * (size_t)va, mb->normals + 3 * (size_t)vb, 12) == 0 &&
                   (!ma->colors || memcmp(ma->colors + 4 * (size_t)va, mb->colors + 4 * (size_t)vb,
                                          4) == 0);
        }
    }
    if (why[0])
        fprintf(stderr, "%s: %s\n", path, why);
    if (!same && b)
        fprintf(stderr, "%s: clusters %u / %u, triangles %llu / %llu\n", path, a->cluster_count,
                b->cluster_count, (unsigned long long)a->triangle_count,
                (unsigned long long)b->triangle_count);
    tw_tileset_destroy(back);
    free(data);
    return same;
}

int main(int argc, char **argv)
{
    if (argc < 2 || argc > 3 || (argc == 3 && strcmp(argv[2], "partial") != 0)) {
        fprintf(stderr, "usage: bake-check DIR [partial]\n");
        return 2;
    }
    const char *dir = argv[1];
    /* partial: a cell may be missing (not baked yet); what is there is checked. */
    const bool partial = argc == 3;
    char path[4096];
    snprintf(path, sizeof(path), "%s/bake.json", dir);
    json_object *rec = json_object_from_file(path);
    CHECK_MSG(rec, "%s does not parse", path);
    snprintf(path, sizeof(path), "%s/tileset.json", dir);
    json_object *tileset = json_object_from_file(path);
    CHECK_MSG(tileset, "%s does not parse", path);
    if (!rec || !tileset)
        return check_summary("bake-check");

    const char *name = json_object_get_string(get(rec, "tileset"));
    const uint64_t seed = json_object_get_uint64(get(rec, "seed"));
    json_object *cells = get(rec, "cells");
    const int64_t i0 = json_object_get_int64(json_object_array_get_idx(cells, 0));
    const int64_t j0 = json_object_get_int64(json_object_array_get_idx(cells, 1));
    const int64_t i1 = json_object_get_int64(json_object_array_get_idx(cells, 2));
    const int64_t j1 = json_object_get_int64(json_object_array_get_idx(cells, 3));
    const uint64_t nx = (uint64_t)(i1 - i0) + 1, ny = (uint64_t)(j1 - j0) + 1;
    uint32_t leaf = 0;
    while ((1ull << leaf) < (nx > ny ? nx : ny))
        leaf++;

    /* tileset.json */
    json_object *asset = get(tileset, "asset"), *root = get(tileset, "root");
    CHECK(strcmp(json_object_get_string(get(asset, "version")), "1.1") == 0);
    CHECK(get(tileset, "geometricError") != NULL);
    json_object *implicit = get(root, "implicitTiling");
    CHECK(implicit != NULL);
    CHECK(strcmp(json_object_get_string(get(implicit, "subdivisionScheme")), "QUADTREE") == 0);
    const int subtree_levels = json_object_get_int(get(implicit, "subtreeLevels"));
    CHECK(subtree_levels >= 1);
    CHECK_MSG(json_object_get_int(get(implicit, "availableLevels")) == (int)leaf + 1,
              "availableLevels %d, finest level %u", json_object_get_int(get(implicit,
              "availableLevels")), leaf);
    CHECK(strcmp(json_object_get_string(get(get(implicit, "subtrees"), "uri")),
                 "subtrees/{level}/{x}/{y}.subtree") == 0);
    CHECK(strcmp(json_object_get_string(get(get(root, "content"), "uri")),
                 "content/{level}/{x}/{y}.glb") == 0);
    json_object *box = get(get(root, "boundingVolume"), "box");
    CHECK(box && json_object_array_length(box) == 12);
    json_object *transform = get(root, "transform");
    CHECK(transform && json_object_array_length(transform) == 16);
    CHECK(strcmp(json_object_get_string(get(root, "refine")), "REPLACE") == 0);

    /* The world that made it. */
    struct tw_tileset *ts = NULL;
    struct tw_tilesets_provider *provider = NULL;
    const struct tw_tile_provider *src = NULL;
    float footprint[2];
    if (tw_tilesets_provider_create(name, seed, 0, NULL, &provider) == TW_OK) {
        src = tw_tilesets_provider_get(provider);
        footprint[0] = src->footprint[0];
        footprint[1] = src->footprint[1];
    } else {
        CHECK(tw_tilesets_builtin(name, seed, 0, NULL, &ts) == TW_OK);
        if (!ts)
            return check_summary("bake-check");
        footprint[0] = ts->footprint[0];
        footprint[1] = ts->footprint[1];
    }
    CHECK(fabs(json_object_get_double(json_object_array_get_idx(transform, 12)) -
               (double)i0 * footprint[0]) < 1e-6);
    CHECK(fabs(json_object_get_double(json_object_array_get_idx(transform, 13)) +
               (double)j0 * footprint[1]) < 1e-6);
    const struct tw_selection sel = {.seed = seed,
                                     .repeat = json_object_get_int64(get(rec, "repeat"))};
    uint64_t with_content = 0;
    for (uint64_t y = 0; y < ny; y++)
        for (uint64_t x = 0; x < nx; x++) {
            const struct tw_cell cell = {i0 + (int64_t)x, j0 + (int64_t)y};
            uint64_t expected = 0;
            struct tw_tileset *gen = NULL;
            const struct tw_tileset *made = ts;
            uint32_t made_proto = 0;
            if (ts) {
                const uint32_t p = tw_tiles_select(ts, &sel, cell);
                expected = p == TW_TILE_EMPTY ? 0 : ts->prototypes[p].triangle_count;
                made_proto = p;
            } else {
                CHECK(tw_tileset_create("check", src->footprint[0], src->footprint[1], &gen) == 0);
                const int rc = src->generate(src->user, cell, gen);
                if (rc == TW_OK) {
                    CHECK(tw_tileset_finish(gen, src->max_cluster_triangles
                                                     ? src->max_cluster_triangles : 2048) == 0);
                    expected = gen->prototypes[0].triangle_count;
                    made = gen;
                } else {
                    CHECK(rc == TW_GENERATE_EMPTY);
                }
            }
            snprintf(path, sizeof(path), "%s/content/%u/%llu/%llu.glb", dir, leaf,
                     (unsigned long long)x, (unsigned long long)y);
            if (expected == 0 || (partial && !exists(path))) {
                CHECK_MSG(expected || !exists(path), "%s: an empty cell has content", path);
                tw_tileset_destroy(gen);
                continue;
            }
            CHECK_MSG(same_tile(path, made, made_proto), "%s: read back as the 3D Tiles provider "
                      "reads it, not the tile that was baked", path);
            tw_tileset_destroy(gen);
            struct tw_gltf_scene *scene = NULL;
            const int rc = tw_gltf_import(path, NULL, NULL, &scene);
            CHECK_MSG(rc == TW_OK, "%s: %s", path, tw_error_to_str(rc));
            if (rc)
                continue;
            with_content++;
            CHECK_MSG(scene->triangle_count == expected, "%s: %llu triangles, the cell shows %llu",
                      path, (unsigned long long)scene->triangle_count,
                      (unsigned long long)expected);
            /* Placed by its node inside its own footprint (glTF: x along i,
             * z along j). */
            const float e = 1e-3f;
            const struct tw_box *b = &scene->bounds;
            CHECK_MSG(b->min[0] >= (float)x * footprint[0] - e &&
                      b->max[0] <= (float)(x + 1) * footprint[0] + e &&
                      b->min[2] >= (float)y * footprint[1] - e &&
                      b->max[2] <= (float)(y + 1) * footprint[1] + e,
                      "%s: bounds [%g %g] x [%g %g] outside its cell", path, b->min[0],
                      b->max[0], b->min[2], b->max[2]);
            tw_gltf_scene_destroy(scene);
        }
    CHECK(with_content > 0);

    /* Coarser levels with content: each inside its block, no more triangles
     * than its children together (as many where no simplification kept
     * within the error its level may add: the children merged as they
     * are). */
    for (uint32_t l = 0; l < leaf; l++) {
        const uint32_t up = leaf - l;
        for (uint64_t y = 0; y <= (ny - 1) >> up; y++)
            for (uint64_t x = 0; x <= (nx - 1) >> up; x++) {
                snprintf(path, sizeof(path), "%s/content/%u/%llu/%llu.glb", dir, l,
                         (unsigned long long)x, (unsigned long long)y);
                if (!exists(path))
                    continue;
                struct tw_gltf_scene *scene = NULL;
                const int rc = tw_gltf_import(path, NULL, NULL, &scene);
                CHECK_MSG(rc == TW_OK, "%s: %s", path, tw_error_to_str(rc));
                if (rc)
                    continue;
                uint64_t below = 0;
                for (int c = 0; c < 4; c++) {
                    struct tw_gltf_scene *cs = NULL;
                    snprintf(path, sizeof(path), "%s/content/%u/%llu/%llu.glb", dir, l + 1,
                             (unsigned long long)(2 * x + (c & 1)),
                             (unsigned long long)(2 * y + (c >> 1)));
                    if (exists(path) && tw_gltf_import(path, NULL, NULL, &cs) == TW_OK)
                        below += cs->triangle_count;
                    tw_gltf_scene_destroy(cs);
                }
                CHECK_MSG(scene->triangle_count > 0 && scene->triangle_count <= below,
                          "level %u tile %llu,%llu: %llu triangles, its children %llu", l,
                          (unsigned long long)x, (unsigned long long)y,
                          (unsigned long long)scene->triangle_count, (unsigned long long)below);
                const double bw = (double)(1ull << up) * footprint[0];
                const double bd = (double)(1ull << up) * footprint[1];
                const struct tw_box *b = &scene->bounds;
                CHECK_MSG(b->min[0] >= x * bw - 1e-3 && b->max[0] <= (x + 1) * bw + 1e-3 &&
                          b->min[2] >= y * bd - 1e-3 && b->max[2] <= (y + 1) * bd + 1e-3,
                          "level %u tile %llu,%llu outside its block", l, (unsigned long long)x,
                          (unsigned long long)y);
                tw_gltf_scene_destroy(scene);
            }
    }

    /* The root subtree. */
    snprintf(path, sizeof(path), "%s/subtrees/0/0/0.subtree", dir);
    size_t size = 0;
    uint8_t *data = read_all(path, &size);
    CHECK_MSG(data && size >= 24, "%s: missing or short", path);
    if (data && size >= 24) {
        CHECK(memcmp(data, "subt", 4) == 0);
        CHECK(data[4] == 1 && data[5] == 0 && data[6] == 0 && data[7] == 0);
        const uint64_t json_len = u64(data + 8), bin_len = u64(data + 16);
        CHECK(json_len % 8 == 0 && bin_len % 8 == 0);
        CHECK_MSG(24 + json_len + bin_len == size, "%s: %zu bytes, the header says %llu", path,
                  size, (unsigned long long)(24 + json_len + bin_len));
        char *text = calloc(1, json_len + 1);
        memcpy(text, data + 24, json_len);
        json_object *st = json_tokener_parse(text);
        CHECK_MSG(st, "%s: its JSON does not parse", path);
        const uint8_t *bin = data + 24 + json_len;
        json_object *views = get(st, "bufferViews");
        json_object *tiles = get(st, "tileAvailability");
        json_object *content = json_object_array_get_idx(get(st, "contentAvailability"), 0);
        json_object *children = get(st, "childSubtreeAvailability");
        CHECK(tiles && content && children);
        for (uint32_t l = 0; st && tiles && content && children && l <= (uint32_t)subtree_levels &&
                             l <= leaf; l++) {
            const uint32_t up = leaf - l;
            for (uint64_t y = 0; y < (1ull << l); y++)
                for (uint64_t x = 0; x < (1ull << l); x++) {
                    /* Available: some cell below it has content. */
                    bool any = false, own = false;
                    for (uint64_t cy = y << up; cy < ((y + 1) << up) && cy < ny; cy++)
                        for (uint64_t cx = x << up; cx < ((x + 1) << up) && cx < nx; cx++) {
                            snprintf(path, sizeof(path), "%s/content/%u/%llu/%llu.glb", dir, leaf,
                                     (unsigned long long)cx, (unsigned long long)cy);
                            any |= exists(path);
                        }
                    snprintf(path, sizeof(path), "%s/content/%u/%llu/%llu.glb", dir, l,
                             (unsigned long long)x, (unsigned long long)y);
                    own = exists(path);
                    const uint64_t m = morton((uint32_t)x, (uint32_t)y);
                    if (l == (uint32_t)subtree_levels) {
                        CHECK_MSG(bit(children, views, bin, m) == any,
                                  "child subtree %u/%llu/%llu", l, (unsigned long long)x,
                                  (unsigned long long)y);
                        continue;
                    }
                    const uint64_t b = ((1ull << (2 * l)) - 1) / 3 + m;
                    CHECK_MSG(bit(tiles, views, bin, b) == (any || own), "tile %u/%llu/%llu", l,
                              (unsigned long long)x, (unsigned long long)y);
                    CHECK_MSG(bit(content, views, bin, b) == own, "content %u/%llu/%llu", l,
                              (unsigned long long)x, (unsigned long long)y);
                }
        }
        json_object_put(st);
        free(text);
    }
    free(data);
    tw_tileset_destroy(ts);
    tw_tilesets_provider_destroy(provider);
    json_object_put(rec);
    json_object_put(tileset);
    return check_summary("bake-check");
}
