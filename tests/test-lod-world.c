/* Levels of detail in a world (DESIGN §17), suite gl: far tiles drawn
 * coarser, every method and the oracle culling the same selection (no
 * missed pixel), what LOD changes in the image measured against full
 * detail, generated tiles too, and full detail when asked for. */
#include <dirent.h>
#include <stdio.h>
#include <sys/stat.h>
#include <stdlib.h>
#include <string.h>

#include "tests/check.h"
#include "tests/headless-world.h"

enum { W = 320, H = 180 };

/* From 120 m up, looking across the city: far tiles fill the top of the
 * image. */
static const struct tw_camera high = {{{0, 0}, {20.0f, 120.0f, 20.0f}}, 35.0f, -8.0f};
/* At eye height down a street. */
static const struct tw_camera street = {{{0, 0}, {0.0f, 1.7f, 2.0f}}, 10.0f, 3.0f};

/* A file of a levels store: its name, inode and time of last use. */
enum { MAX_STORED = 1024 };
struct stored {
    char name[64];
    unsigned long long inode;
    long long mtime_ns;
};

/* The files of levels in dir, at most max of them into out; their number. */
static int stored_files(const char *dir, struct stored *out, int max)
{
    DIR *d = opendir(dir);
    int n = 0;
    for (const struct dirent *e; d && (e = readdir(d));) {
        if (e->d_name[0] == '.' || !strstr(e->d_name, ".levels"))
            continue;
        char path[512];
        struct stat st;
        snprintf(path, sizeof(path), "%s/%s", dir, e->d_name);
        if (n < max && stat(path, &st) == 0) {
            snprintf(out[n].name, sizeof(out[n].name), "%.63s", e->d_name);
            out[n].inode = (unsigned long long)st.st_ino;
            out[n].mtime_ns = (long long)st.st_mtim.tv_sec * 1000000000ll + st.st_mtim.tv_nsec;
        }
        n++;
    }
    if (d)
        closedir(d);
    return n;
}

/* Where the worlds keep their levels: the test run's store, unless set. */
static const char *store_dir;

static struct tw_world *make_world(struct tw_context *ctx, const struct tw_tileset *ts,
                                   const struct tw_tile_provider *provider, float max_screen_error,
                                   bool verify)
{
    struct tw_world_settings s = world_settings(ctx, ts, W, H, 1, 800.0f);
    if (provider) {
        s.tileset = NULL;
        s.provider = provider;
        s.workers = 1;
    }
    s.max_screen_error = max_screen_error;
    if (store_dir)
        s.levels_cache_dir = store_dir;
    s.verify = verify;
    s.deterministic = true;
    struct tw_world *w = NULL;
    if (tw_world_create(&s, &w) != TW_OK)
        return NULL;
    return w;
}

static bool frame(struct tw_world *w, enum tw_method m, const struct tw_camera *cam,
                  struct tw_frame_stats *st)
{
    return tw_world_set_method_or_limit(w, m) == TW_OK && tw_world_frame(w, cam, st) == TW_OK &&
           tw_world_finish(w, st) == TW_OK;
}

/* The triangles vfc draws from cam at full detail, and at max_screen_error. */
static void triangles_of(struct tw_context *ctx, const struct tw_tileset *ts,
                         const struct tw_tile_provider *provider, const struct tw_camera *cam,
                         float max_screen_error, uint64_t *triangles)
{
    *triangles = 0;
    struct tw_world *w = make_world(ctx, ts, provider, max_screen_error, false);
    CHECK(w != NULL);
    struct tw_frame_stats st;
    if (w && frame(w, TW_METHOD_VFC, cam, &st))
        *triangles = st.triangles;
    tw_world_destroy(w);
}

/* Every method misses nothing that the oracle, at the same levels, sees;
 * the image differs from full detail in few pixels at 1 px. */
static void test_methods(struct tw_context *ctx, const struct tw_tileset *ts)
{
    struct tw_world *w = make_world(ctx, ts, NULL, 1.0f, true);
    CHECK(w != NULL);
    if (!w)
        return;
    static const enum tw_method methods[] = {TW_METHOD_VFC, TW_METHOD_TILEQUERY_CHC,
                                             TW_METHOD_HZB, TW_METHOD_BOX_ORACLE};
    const struct tw_camera *cams[] = {&high, &street};
    uint64_t high_pixels = 0;
    for (size_t c = 0; c < 2; c++)
        for (int pass = 0; pass < 2; pass++)  /* the second warm */
            for (size_t m = 0; m < sizeof(methods) / sizeof(methods[0]); m++) {
                struct tw_frame_stats st;
                CHECK(frame(w, methods[m], cams[c], &st));
                CHECK_MSG(st.missed_pixels == 0, "%s, camera %zu: %llu pixels missed",
                          tw_method_name(methods[m]), c, (unsigned long long)st.missed_pixels);
                CHECK(st.lod_pixels <= st.lod_pixels_exact);
                /* Down a street, levels chosen for 1 px change a few
                 * pixels in a thousand (a far roof line, a window gone).
                 * From high up the far blocks' windows, a fraction of a
                 * pixel each, go: README "Levels of detail" has the
                 * figures. */
                if (c == 1)
                    CHECK_MSG(st.lod_pixels <= W * H / 200, "%s, street: %llu pixels differ",
                              tw_method_name(methods[m]), (unsigned long long)st.lod_pixels);
                else
                    high_pixels = st.lod_pixels;
            }
    tw_world_destroy(w);

    /* A coarse bound changes more: the measure sees what LOD changes. */
    w = make_world(ctx, ts, NULL, 16.0f, true);
    CHECK(w != NULL);
    struct tw_frame_stats st;
    if (w && frame(w, TW_METHOD_VFC, &high, &st)) {
        CHECK_MSG(st.lod_pixels > high_pixels, "16 px: %llu pixels differ, 1 px: %llu",
                  (unsigned long long)st.lod_pixels, (unsigned long long)high_pixels);
        CHECK(st.lod_depth_m > 0.0);
        CHECK(st.missed_pixels == 0);
    }
    tw_world_destroy(w);
    /* Full detail: nothing measured, nothing differs. */
    w = make_world(ctx, ts, NULL, TW_FULL_DETAIL, true);
    if (w && frame(w, TW_METHOD_VFC, &high, &st))
        CHECK(st.lod_pixels == 0 && st.lod_depth_m == 0.0);
    tw_world_destroy(w);
}

int main(void)
{
    struct tw_context *ctx;
    struct tw_tileset *ts;
    if (!open_headless(W, H, "city", 1, &ctx, &ts))
        return 1;
    /* Far tiles drawn coarser: fewer triangles from high up, a quarter
     * fewer again with a bound of 8 px. */
    uint64_t full = 0, lod1 = 0, lod8 = 0;
    triangles_of(ctx, ts, NULL, &high, TW_FULL_DETAIL, &full);
    triangles_of(ctx, ts, NULL, &high, 1.0f, &lod1);
    triangles_of(ctx, ts, NULL, &high, 8.0f, &lod8);
    CHECK_MSG(lod1 < full && lod8 < lod1 * 3 / 4 && lod8 > 0,
              "triangles: full %llu, 1 px %llu, 8 px %llu", (unsigned long long)full,
              (unsigned long long)lod1, (unsigned long long)lod8);
    test_methods(ctx, ts);

    /* Generated tiles have levels too. */
    struct tw_tilesets_provider *gen = NULL;
    CHECK(tw_tilesets_provider_create("city-gen", 1, 0, &test_log, &gen) == TW_OK);
    uint64_t gen_full = 0, gen_lod = 0;
    triangles_of(ctx, NULL, tw_tilesets_provider_get(gen), &high, TW_FULL_DETAIL, &gen_full);
    /* A world keeps its tiles' levels in its store (a folder of its own
     * here, empty), and the worlds after it read them back. */
    char root[] = "/tmp/tw-test-lod-world-XXXXXX";
    CHECK(mkdtemp(root) != NULL);
    store_dir = root;
    triangles_of(ctx, NULL, tw_tilesets_provider_get(gen), &high, 1.0f, &gen_lod);
    static struct stored before[MAX_STORED];
    const int files = stored_files(root, before, MAX_STORED);
    CHECK_MSG(files > 0 && files <= MAX_STORED, "the world kept %d files of levels in %s", files, root);
    CHECK_MSG(gen_lod > 0 && gen_lod < gen_full, "city-gen triangles: full %llu, 1 px %llu",
              (unsigned long long)gen_full, (unsigned long long)gen_lod);
    struct tw_world *w = make_world(ctx, NULL, tw_tilesets_provider_get(gen), 1.0f, true);
    CHECK(w != NULL);
    struct tw_frame_stats st;
    for (int k = 0; w && k < 2; k++) {
        CHECK(frame(w, TW_METHOD_TILEQUERY_CHC, &high, &st));
        CHECK_MSG(st.missed_pixels == 0, "city-gen: %llu pixels missed",
                  (unsigned long long)st.missed_pixels);
    }
    tw_world_destroy(w);
    /* Read back: the same triangles, and the files read (a read marks
     * its file used now), not written again (a write replaces the file). */
    uint64_t again = 0;
    triangles_of(ctx, NULL, tw_tilesets_provider_get(gen), &high, 1.0f, &again);
    CHECK_MSG(again == gen_lod, "city-gen triangles read back %llu, built %llu",
              (unsigned long long)again, (unsigned long long)gen_lod);
    static struct stored after[MAX_STORED];
    CHECK(stored_files(root, after, MAX_STORED) == files);
    int kept = 0, read = 0;
    for (int i = 0; i < files && i < MAX_STORED; i++)
        for (int k = 0; k < files && k < MAX_STORED; k++)
            if (strcmp(before[i].name, after[k].name) == 0) {
                kept += before[i].inode == after[k].inode;
                read += after[k].mtime_ns > before[i].mtime_ns;
            }
    CHECK_MSG(kept == files && read > 0, "of %d files, %d kept, %d read back", files, kept, read);
    store_dir = NULL;
    char cmd[200];
    snprintf(cmd, sizeof(cmd), "rm -rf '%s'", root);
    CHECK(system(cmd) == 0);
    tw_tilesets_provider_destroy(gen);
    tw_tileset_destroy(ts);
    tw_context_destroy(ctx);
    return check_summary("test-lod-world");
}
