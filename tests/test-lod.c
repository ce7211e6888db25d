/*
 * Levels of detail (tiles/lod.c, DESIGN §17): each level coarser than the
 * one before, its error never smaller, within its prototype's box, its
 * colours those of its instances' materials; the pick by error.
 */
#include "check.h"
#include "meshes.h"
#include "tiles/tiles-internal.h"
#include "tileworld/tiles.h"

#include <dirent.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>


static bool box_inside(const struct tw_box *in, const struct tw_box *out)
{
    for (int a = 0; a < 3; a++)
        if (in->min[a] < out->min[a] || in->max[a] > out->max[a])
            return false;
    return true;
}

static void *stop_soon(void *arg)
{
    const struct timespec t = {0, 20 * 1000000L};
    nanosleep(&t, NULL);
    atomic_store((atomic_bool *)arg, true);
    return NULL;
}

struct shared_call {
    const struct tw_tileset *ts;
    const struct tw_lods *got;
    int err;
};

static void *ask_shared(void *arg)
{
    struct shared_call *c = arg;
    c->err = tw_lods_of_tileset(c->ts, NULL, &c->got);
    return NULL;
}

/* The levels kept with a tileset: two threads asking at once get one
 * build, the same as tw_lods_build's; later calls get it again. */
static void test_shared(const struct tw_tileset *ts, const struct tw_lods *built)
{
    struct shared_call a = {ts, NULL, -99}, b = {ts, NULL, -99};
    pthread_t ta, tb;
    const bool sa = pthread_create(&ta, NULL, ask_shared, &a) == 0;
    const bool sb = pthread_create(&tb, NULL, ask_shared, &b) == 0;
    CHECK(sa && sb);
    if (sa)
        pthread_join(ta, NULL);
    if (sb)
        pthread_join(tb, NULL);
    if (!sa || !sb)
        return;
    CHECK(a.err == TW_OK && b.err == TW_OK && a.got != NULL && a.got == b.got);
    const struct tw_lods *again = NULL;
    CHECK(tw_lods_of_tileset(ts, NULL, &again) == TW_OK && again == a.got);
    if (!a.got)
        return;
    CHECK(a.got->source_count == built->source_count);
    CHECK(a.got->levels && built->levels &&
          a.got->levels->prototype_count == built->levels->prototype_count);
    for (uint32_t p = 0; p < built->source_count; p++) {
        CHECK(a.got->count[p] == built->count[p] && a.got->first[p] == built->first[p]);
        for (uint32_t k = 0; k < built->count[p]; k++)
            CHECK(a.got->error[built->first[p] + k] == built->error[built->first[p] + k]);
    }
}

/* Whether a and b are the same levels: counts, errors and every level's
 * geometry, byte for byte. */
static bool same_levels(const struct tw_lods *a, const struct tw_lods *b)
{
    if (a->source_count != b->source_count || !a->levels != !b->levels)
        return false;
    for (uint32_t p = 0; p < a->source_count; p++) {
        if (a->count[p] != b->count[p] || a->first[p] != b->first[p])
            return false;
        for (uint32_t k = 0; k < a->count[p]; k++)
            if (a->error[a->first[p] + k] != b->error[b->first[p] + k])
                return false;
    }
    if (!a->levels)
        return true;
    if (a->levels->mesh_count != b->levels->mesh_count ||
        a->levels->prototype_count != b->levels->prototype_count)
        return false;
    for (uint32_t m = 0; m < a->levels->mesh_count; m++) {
        const struct tw_mesh *x = &a->levels->meshes[m], *y = &b->levels->meshes[m];
        if (x->vertex_count != y->vertex_count || x->triangle_count != y->triangle_count ||
            !x->colors != !y->colors ||
            memcmp(x->positions, y->positions, 12 * (size_t)x->vertex_count) != 0 ||
            memcmp(x->normals, y->normals, 12 * (size_t)x->vertex_count) != 0 ||
            memcmp(x->indices, y->indices, 12 * (size_t)x->triangle_count) != 0 ||
            (x->colors && memcmp(x->colors, y->colors, 4 * (size_t)x->vertex_count) != 0))
            return false;
    }
    return true;
}

/* The files a store's folder holds: their number, and with damage, each
 * one changed (1: a byte of its middle flipped, 2: cut to half). */
static int store_files(const char *dir, int damage)
{
    DIR *d = opendir(dir);
    if (!d)
        return -1;
    int n = 0;
    const struct dirent *e;
    while ((e = readdir(d))) {
        const size_t len = strlen(e->d_name);
        if (len < 8 || strcmp(e->d_name + len - 7, ".levels") != 0)
            continue;
        n++;
        char path[512];
        snprintf(path, sizeof(path), "%s/%s", dir, e->d_name);
        struct stat st;
        if (!damage || stat(path, &st) != 0)
            continue;
        if (damage == 2) {
            CHECK(truncate(path, st.st_size / 2) == 0);
            continue;
        }
        FILE *f = fopen(path, "r+b");
        CHECK(f != NULL);
        if (!f)
            continue;
        fseek(f, st.st_size / 2, SEEK_SET);
        const int c = fgetc(f);
        fseek(f, st.st_size / 2, SEEK_SET);
        fputc(c ^ 0x40, f);
        fclose(f);
    }
    closedir(d);
    return n;
}

/* The levels' store: what it reads back is what was built, byte for byte
 * (a box level too); a file damaged or cut is built again, not trusted;
 * past its byte limit the oldest files go; a folder that cannot be made
 * says why; its parents are made. */
static void test_store(const struct tw_tileset *ts, const struct tw_lods *built)
{
    char root[] = "/tmp/tw-test-lod-XXXXXX";
    CHECK(mkdtemp(root) != NULL);
    char dir[128], why[320] = "";
    snprintf(dir, sizeof(dir), "%s/a/b/levels", root);
    struct tw_file_cache *store = NULL, *again = NULL;
    CHECK(tw_lods_store(dir, 0, &store, why, sizeof(why)) == TW_OK && store != NULL);
    CHECK(tw_lods_store(dir, 0, &again, why, sizeof(why)) == TW_OK && again == store);
    if (!store)
        return;
    /* Built and written: one file a prototype with levels. */
    uint32_t with_levels = 0;
    for (uint32_t p = 0; p < built->source_count; p++)
        with_levels += built->count[p] > 0;
    struct tw_lods l;
    CHECK(tw_lods_build(ts, 256, store, NULL, &l) == TW_OK && l.stored == 0);
    CHECK(same_levels(&l, built));
    tw_lods_free(&l);
    CHECK_MSG(store_files(dir, 0) >= (int)with_levels && with_levels > 0, "%d files, %u prototypes",
              store_files(dir, 0), with_levels);
    /* Read back: the same levels. */
    CHECK(tw_lods_build(ts, 256, store, NULL, &l) == TW_OK);
    CHECK_MSG(l.stored >= with_levels, "%u prototypes read back of %u", l.stored, with_levels);
    CHECK(same_levels(&l, built));
    tw_lods_free(&l);
    /* Damaged, then cut: built again (and written again). */
    for (int damage = 1; damage <= 2; damage++) {
        CHECK(store_files(dir, damage) > 0);
        CHECK(tw_lods_build(ts, 256, store, NULL, &l) == TW_OK);
        CHECK_MSG(l.stored == 0, "damage %d: %u prototypes read back", damage, l.stored);
        CHECK(same_levels(&l, built));
        tw_lods_free(&l);
    }
    CHECK(tw_lods_build(ts, 256, store, NULL, &l) == TW_OK && l.stored >= with_levels);
    tw_lods_free(&l);
    /* A store of 1 kB holds none of these (each file is larger). */
    char small[160];
    snprintf(small, sizeof(small), "%s/small", root);
    struct tw_file_cache *tiny = NULL;
    CHECK(tw_lods_store(small, 1024, &tiny, why, sizeof(why)) == TW_OK);
    CHECK(tw_lods_build(ts, 256, tiny, NULL, &l) == TW_OK && same_levels(&l, built));
    tw_lods_free(&l);
    CHECK(store_files(small, 0) == 0);
    /* A folder under a file cannot be made. */
    char bad[160];
    snprintf(bad, sizeof(bad), "%s/a/b/levels/%s", root, "x");
    FILE *f = fopen(bad, "w");
    CHECK(f != NULL);
    if (f)
        fclose(f);
    snprintf(bad, sizeof(bad), "%s/a/b/levels/x/y", root);
    struct tw_file_cache *none = NULL;
    why[0] = '\0';
    CHECK(tw_lods_store(bad, 0, &none, why, sizeof(why)) == TW_ERR_IO && none == NULL);
    CHECK_MSG(strstr(why, "cannot be made") != NULL, "%s", why);
    CHECK(tw_lods_store("", 0, &none, why, sizeof(why)) == TW_ERR_INVALID);
    char cmd[200];
    snprintf(cmd, sizeof(cmd), "rm -rf '%s'", root);
    CHECK(system(cmd) == 0);
}

/* The stop (a tile's worker at the world's destroy): set before, nothing
 * is built; set 20 ms into a build of about 0.57 s of CPU time (here), the build gives
 * up with TW_ERR_STATE and leaves nothing to free. */
static void test_stop(void)
{
    struct tw_tileset *ts;
    CHECK(tw_tileset_create("rough", 40, 40, &ts) == TW_OK);
    const int proto = tw_tileset_add_prototype(ts, "rough", 1.0f);
    CHECK(add_rough_ground(ts, proto, 160, 40.0f, 8, 99));
    CHECK(tw_tileset_finish(ts, 2048) == TW_OK);
    atomic_bool stop;
    atomic_init(&stop, true);
    struct tw_lods l;
    CHECK(tw_lods_build(ts, 2048, NULL, &stop, &l) == TW_ERR_STATE && l.levels == NULL &&
          l.first == NULL);
    atomic_store(&stop, false);
    pthread_t t;
    const bool started = pthread_create(&t, NULL, stop_soon, &stop) == 0;
    CHECK(started);
    if (started) {
        CHECK(tw_lods_build(ts, 2048, NULL, &stop, &l) == TW_ERR_STATE && l.levels == NULL);
        pthread_join(t, NULL);
    }
    tw_tileset_destroy(ts);
}

int main(void)
{
    struct tw_tileset *ts;
    CHECK(tw_tileset_create("lod", 40, 40, &ts) == TW_OK);
    const int red = tw_tileset_add_material(ts, (const float[4]){1, 0, 0, 1});
    const int green = tw_tileset_add_material(ts, (const float[4]){0, 1, 0, 1});
    const int cube = add_cube(ts);
    const int terrain = add_grid(ts, 64, 40.0f, false);
    CHECK(red >= 0 && green >= 0 && cube >= 0 && terrain >= 0);
    /* 0: a block of 400 small buildings (closed boxes: edge collapse stalls) */
    const int block = tw_tileset_add_prototype(ts, "block", 1.0f);
    CHECK(add_houses(ts, block, cube, red));
    /* 1: terrain, green */
    const int field = tw_tileset_add_prototype(ts, "field", 1.0f);
    CHECK(tw_tileset_add_instance(ts, (uint32_t)field, (uint32_t)terrain, (uint32_t)green, NULL) >= 0);
    /* 2: one cube: too small to simplify */
    const int lone = tw_tileset_add_prototype(ts, "lone", 1.0f);
    CHECK(tw_tileset_add_instance(ts, (uint32_t)lone, (uint32_t)cube, (uint32_t)red, NULL) >= 0);
    /* 3: a facade of grey wall and dark windows */
    int wall_mesh, win_mesh;
    add_facade(ts, 32, &wall_mesh, &win_mesh);
    const int grey = tw_tileset_add_material(ts, (const float[4]){0.6f, 0.6f, 0.6f, 1});
    const int dark = tw_tileset_add_material(ts, (const float[4]){0.1f, 0.1f, 0.2f, 1});
    const int facade = tw_tileset_add_prototype(ts, "facade", 1.0f);
    CHECK(wall_mesh >= 0 && win_mesh >= 0 && grey >= 0 && dark >= 0 && facade >= 0);
    CHECK(tw_tileset_add_instance(ts, (uint32_t)facade, (uint32_t)wall_mesh, (uint32_t)grey, NULL) >= 0);
    CHECK(tw_tileset_add_instance(ts, (uint32_t)facade, (uint32_t)win_mesh, (uint32_t)dark, NULL) >= 0);
    ts->merge_triangles = 1;
    CHECK(tw_tileset_finish(ts, 256) == TW_OK);

    struct tw_lods l;
    CHECK(tw_lods_build(ts, 256, NULL, NULL, &l) == TW_OK);
    CHECK(l.levels != NULL && l.source_count == 4);
    /* The facade: a level that takes windows out says so. A window gone
     * is off by the distance to the next one or its own size (at least
     * 1 m here), not by the 5 cm it stands out of the wall: a level of
     * less error keeps every window's two triangles. */
    CHECK_MSG(l.count[3] >= 1, "%u levels of the facade", l.count[3]);
    for (uint32_t k = 0; l.levels && k < l.count[3]; k++) {
        const struct tw_prototype *lv = &l.levels->prototypes[l.first[3] + k];
        const struct tw_mesh *m = &l.levels->meshes[lv->instances[0].mesh];
        uint32_t dark_triangles = 0;
        for (uint32_t t = 0; m->colors && t < m->triangle_count; t++)
            dark_triangles += m->colors[4 * m->indices[3 * t] + 0] < 64;
        const float e = l.error[l.first[3] + k];
        CHECK_MSG(e >= 1.0f || dark_triangles >= 200,
                  "facade level %u: error %g m with %u of 200 window triangles", k + 1, e,
                  dark_triangles);
    }
    /* The block: its houses' boxes cannot be made coarser, only fewer
     * (a house gone is off by its own size); one level at least. */
    CHECK_MSG(l.count[0] >= 1, "%u levels of the block", l.count[0]);
    CHECK_MSG(l.count[1] >= 3, "%u levels of the field", l.count[1]);
    CHECK(l.count[2] == 0);
    /* Every prototype that can be simplified ends at a box at most (12
     * triangles), whatever the simplifier leaves: far enough away, a cell
     * of a block of hierarchical cells is drawn as one. */
    for (uint32_t p = 0; p < 4 && l.levels; p++) {
        if (p == 2 || l.count[p] == 0)
            continue;
        const struct tw_prototype *last = &l.levels->prototypes[l.first[p] + l.count[p] - 1];
        CHECK_MSG(last->triangle_count <= 12, "prototype %u ends at %llu triangles", p,
                  (unsigned long long)last->triangle_count);
    }
    for (uint32_t p = 0; p < 2 && l.levels; p++) {
        uint64_t previous = ts->prototypes[p].triangle_count;
        float previous_error = 0.0f;
        for (uint32_t k = 0; k < l.count[p]; k++) {
            const struct tw_prototype *lv = &l.levels->prototypes[l.first[p] + k];
            const float e = l.error[l.first[p] + k];
            CHECK_MSG((double)lv->triangle_count <= 0.75 * (double)previous,
                      "prototype %u level %u: %llu triangles after %llu", p, k + 1,
                      (unsigned long long)lv->triangle_count, (unsigned long long)previous);
            CHECK_MSG(e >= previous_error && isfinite(e) && e > 0.0f,
                      "prototype %u level %u: error %g after %g", p, k + 1, e, previous_error);
            CHECK(box_inside(&lv->box, &ts->prototypes[p].box));
            CHECK(lv->cluster_count >= 1);
            for (uint32_t c = 0; c < lv->cluster_count; c++)
                CHECK(lv->clusters[c].triangle_count <= 256);
            /* Colours baked from the material: every vertex red, or green. */
            const struct tw_mesh *m = &l.levels->meshes[lv->instances[0].mesh];
            CHECK(m->colors != NULL);
            bool colour_ok = true;
            for (uint32_t v = 0; m->colors && v < m->vertex_count; v++) {
                const uint8_t *c = m->colors + 4 * v;
                colour_ok &= p == 0 ? c[0] == 255 && c[1] == 0 : c[0] == 0 && c[1] == 255;
            }
            CHECK_MSG(colour_ok, "prototype %u level %u: a vertex not of its material", p, k + 1);
            previous = lv->triangle_count;
            previous_error = e;
        }
        /* The field's first level keeps its shape within a fraction of a
         * metre; its coarsest is much coarser. */
        if (p == 1 && l.count[1] >= 3) {
            CHECK_MSG(l.error[l.first[1]] < 0.2f, "first level error %g", l.error[l.first[1]]);
            CHECK(l.error[l.first[1] + l.count[1] - 1] > l.error[l.first[1]]);
        }
    }
    /* The pick: 0 without an error to spend, every level with a large one,
     * level k + 1 at exactly level k + 1's error. */
    CHECK(tw_lods_pick(&l, 1, 0.0f) == 0);
    CHECK(tw_lods_pick(&l, 1, -1.0f) == 0);
    CHECK(tw_lods_pick(&l, 1, 1e9f) == l.count[1]);
    CHECK(tw_lods_pick(&l, 2, 1e9f) == 0);
    CHECK(tw_lods_pick(&l, 7, 1e9f) == 0);
    for (uint32_t k = 0; k < l.count[1]; k++)
        CHECK(tw_lods_pick(&l, 1, l.error[l.first[1] + k]) >= k + 1);
    CHECK(tw_lods_pick(&l, 1, 0.5f * l.error[l.first[1]]) == 0 || l.error[l.first[1]] == 0.0f);
    CHECK(tw_lods_bytes(&l) > tw_tileset_geometry_bytes(l.levels) / 2);
    test_shared(ts, &l);
    test_store(ts, &l);
    tw_lods_free(&l);
    tw_lods_free(&l);   /* twice: zeroed */
    CHECK(l.levels == NULL && l.first == NULL);

    /* Unfinished: refused. */
    struct tw_tileset *raw;
    CHECK(tw_tileset_create("raw", 10, 10, &raw) == TW_OK);
    CHECK(tw_lods_build(raw, 256, NULL, NULL, &l) == TW_ERR_INVALID && l.levels == NULL);
    const struct tw_lods *none = &l;
    CHECK(tw_lods_of_tileset(raw, NULL, &none) == TW_ERR_INVALID && none == NULL);
    tw_tileset_destroy(raw);
    tw_tileset_destroy(ts);
    test_stop();
    return check_summary("test-lod");
}
