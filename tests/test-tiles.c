/* Unit tests of tiles/: grid math, coordinates, selection, the tileset model. */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "tileworld/tiles.h"
#include "tiles/pages.h"
#include "tests/check.h"
#include "tiles/tiles-internal.h"

static uint64_t rng_state = 0x1234567;

static uint64_t next_random(void)
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 7;
    rng_state ^= rng_state << 17;
    return rng_state;
}

static void test_floor_div_mod(void)
{
    CHECK(tw_tiles_floor_div(7, 3) == 2);
    CHECK(tw_tiles_floor_div(-7, 3) == -3);
    CHECK(tw_tiles_floor_div(-6, 3) == -2);
    CHECK(tw_tiles_floor_mod(-7, 3) == 2);
    CHECK(tw_tiles_floor_mod(-6, 3) == 0);
    CHECK(tw_tiles_floor_mod(INT64_MIN, 7) >= 0);
    CHECK(tw_tiles_floor_div(INT64_MIN, 1) == INT64_MIN);
    for (int k = 0; k < 10000; k++) {
        const int64_t a = (int64_t)next_random();
        const int64_t b = (int64_t)(next_random() % 1000000) + 1;
        const int64_t q = tw_tiles_floor_div(a, b), r = tw_tiles_floor_mod(a, b);
        CHECK(r >= 0 && r < b);
        /* a == q * b + r, checked in wrapping unsigned arithmetic. */
        CHECK((uint64_t)a == (uint64_t)q * (uint64_t)b + (uint64_t)r);
    }
}

/* Cells up to +-2^62: moving whole footprints between local and cell is
 * exact, and the local remainder is preserved bit for bit. */
static void test_normalize_round_trip(void)
{
    const float w = 80.0f, d = 64.0f;
    const int64_t limit = (int64_t)1 << 62;
    for (int k = 0; k < 20000; k++) {
        struct tw_cell c = {(int64_t)(next_random() % (uint64_t)limit),
                            (int64_t)(next_random() % (uint64_t)limit)};
        if (next_random() & 1) c.i = -c.i;
        if (next_random() & 1) c.j = -c.j;
        if (k < 4) {
            c.i = k & 1 ? limit : -limit;
            c.j = k & 2 ? limit : -limit;
        }
        const float x = (float)(next_random() % 640) / 8.0f;   /* [0, 80), exact */
        const float z = (float)(next_random() % 512) / 8.0f;   /* [0, 64), exact */
        const int64_t ki = (int64_t)(next_random() % 2001) - 1000;
        const int64_t kj = (int64_t)(next_random() % 2001) - 1000;
        struct tw_world_pos p = {c, {x + (float)ki * w, 1.7f, z + (float)kj * d}};
        const int err = tw_tiles_normalize(&p, w, d);
        const bool overflow = (ki > 0 && c.i > INT64_MAX - ki) || (kj > 0 && c.j > INT64_MAX - kj);
        if (overflow) {
            CHECK(err == TW_ERR_INVALID);
            continue;
        }
        CHECK(err == TW_OK);
        CHECK(p.cell.i == c.i + ki);
        CHECK(p.cell.j == c.j + kj);
        CHECK(p.local[0] == x);
        CHECK(p.local[2] == z);
        CHECK(p.local[1] == 1.7f);
        CHECK(p.local[0] >= 0.0f && p.local[0] < w);
        CHECK(p.local[2] >= 0.0f && p.local[2] < d);

        /* The offset of a nearby cell is exact wherever the pair lies. */
        struct tw_cell near = {p.cell.i + 3, p.cell.j - 2};
        if (p.cell.i > INT64_MAX - 3 || p.cell.j < INT64_MIN + 2)
            continue;
        float off[3];
        tw_tiles_cell_offset(near, p.cell, w, d, off);
        CHECK(off[0] == 240.0f && off[1] == 0.0f && off[2] == -128.0f);
    }
    /* Non-finite offsets and overflow are refused, the position untouched. */
    struct tw_world_pos bad = {{0, 0}, {NAN, 0, 0}};
    CHECK(tw_tiles_normalize(&bad, 80, 80) == TW_ERR_INVALID);
    struct tw_world_pos edge = {{INT64_MAX, 0}, {160.0f, 0, 0}};
    CHECK(tw_tiles_normalize(&edge, 80, 80) == TW_ERR_INVALID);
    CHECK(edge.cell.i == INT64_MAX && edge.local[0] == 160.0f);
    struct tw_world_pos neg = {{0, 0}, {-0.25f, 0, -80.0f}};
    CHECK(tw_tiles_normalize(&neg, 80, 80) == TW_OK);
    CHECK(neg.cell.i == -1 && neg.local[0] == 79.75f && neg.cell.j == -1 && neg.local[2] == 0.0f);
    /* A tiny negative offset rounds to the footprint: it must wrap to 0. */
    struct tw_world_pos tiny = {{5, 5}, {-1e-9f, 0, 0}};
    CHECK(tw_tiles_normalize(&tiny, 80, 80) == TW_OK);
    CHECK(tiny.local[0] >= 0.0f && tiny.local[0] < 80.0f);
}

static int make_tileset(struct tw_tileset **out, uint32_t prototypes, const float *weights)
{
    struct tw_tileset *ts = NULL;
    int err = tw_tileset_create("test", 10.0f, 10.0f, &ts);
    if (err)
        return err;
    const float pos[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
    const uint32_t idx[] = {0, 1, 2, 1, 3, 2};
    const int mesh = tw_tileset_add_mesh(ts, pos, NULL, 4, idx, 2);
    const int mat = tw_tileset_add_material(ts, (const float[4]){1, 0, 0, 1});
    for (uint32_t p = 0; p < prototypes; p++) {
        const int proto = tw_tileset_add_prototype(ts, "p", weights ? weights[p] : 1.0f);
        float t[12] = {1, 0, 0, (float)p, 0, 1 + (float)p, 0, 0, 0, 0, 1, 2};
        tw_tileset_add_instance(ts, (uint32_t)proto, (uint32_t)mesh, (uint32_t)mat, t);
    }
    err = tw_tileset_finish(ts, 0);
    *out = ts;
    return err;
}

static uint32_t select_diagonal(void *user, struct tw_cell c)
{
    (void)user;
    return (uint32_t)tw_tiles_floor_mod(c.i + c.j, 3);
}

static void test_selection(void)
{
    const float weights[4] = {1, 2, 3, 4};
    struct tw_tileset *ts = NULL;
    CHECK(make_tileset(&ts, 4, weights) == TW_OK);
    if (!ts)
        return;
    struct tw_selection sel = {.seed = 42};
    uint32_t counts[4] = {0};
    const uint32_t n = 200000;
    for (uint32_t k = 0; k < n; k++) {
        const struct tw_cell c = {(int64_t)(k % 500) - 250, (int64_t)(k / 500) - 200};
        const uint32_t p = tw_tiles_select(ts, &sel, c);
        CHECK(p < 4);
        CHECK(p == tw_tiles_select(ts, &sel, c));      /* a pure function */
        counts[p < 4 ? p : 0]++;
    }
    /* Frequencies follow the weights within 2% absolute. */
    for (int p = 0; p < 4; p++) {
        const double share = counts[p] / (double)n, expected = weights[p] / 10.0;
        CHECK(fabs(share - expected) < 0.02);
    }
    /* A different seed gives a different map. */
    struct tw_selection other = {.seed = 43};
    uint32_t same = 0;
    for (int64_t k = 0; k < 1000; k++)
        same += tw_tiles_select(ts, &sel, (struct tw_cell){k, 7}) ==
                tw_tiles_select(ts, &other, (struct tw_cell){k, 7});
    CHECK(same < 600);

    /* Periodic selection repeats with period P, as far as 2^40 and beyond. */
    struct tw_selection per = {.seed = 9, .repeat = 4};
    const int64_t far = (int64_t)1 << 40;
    for (int64_t i = -8; i < 8; i++)
        for (int64_t j = -8; j < 8; j++) {
            const uint32_t a = tw_tiles_select(ts, &per, (struct tw_cell){i, j});
            CHECK(a == tw_tiles_select(ts, &per, (struct tw_cell){i + far, j + far}));
            CHECK(a == tw_tiles_select(ts, &per, (struct tw_cell){i - 4 * far, j + 8}));
            CHECK(a == tw_tiles_select(ts, &per, (struct tw_cell){i + 4, j - 4}));
        }
    /* Not every cell of a period shows the same prototype. */
    uint32_t seen = 0;
    for (int64_t i = 0; i < 4; i++)
        for (int64_t j = 0; j < 4; j++)
            seen |= 1u << tw_tiles_select(ts, &per, (struct tw_cell){i, j});
    CHECK(seen != 1u && seen != 2u && seen != 4u && seen != 8u);

    /* A host callback replaces the hash. */
    struct tw_selection host = {.fn = select_diagonal};
    CHECK(tw_tiles_select(ts, &host, (struct tw_cell){5, 5}) == 1);
    CHECK(tw_tiles_select(ts, &host, (struct tw_cell){-1, 0}) == 2);
    tw_tileset_destroy(ts);
}

static void test_tileset_builder(void)
{
    struct tw_tileset *ts = NULL;
    CHECK(tw_tileset_create("t", 0.0f, 1.0f, &ts) == TW_ERR_INVALID);
    CHECK(tw_tileset_create("t", 20.0f, 20.0f, &ts) == TW_OK);
    if (!ts)
        return;
    /* A 30x30 grid of quads: 1800 triangles. */
    enum { N = 30 };
    float *pos = malloc(sizeof(float) * 3 * (N + 1) * (N + 1));
    uint32_t *idx = malloc(sizeof(uint32_t) * 6 * N * N);
    for (int z = 0; z <= N; z++)
        for (int x = 0; x <= N; x++) {
            float *p = pos + 3 * (z * (N + 1) + x);
            p[0] = (float)x * 0.5f;
            p[1] = (float)((x * 7 + z * 3) % 5) * 0.1f;
            p[2] = (float)z * 0.5f;
        }
    for (int z = 0; z < N; z++)
        for (int x = 0; x < N; x++) {
            uint32_t *q = idx + 6 * (z * N + x);
            const uint32_t a = (uint32_t)(z * (N + 1) + x), b = a + 1, c = a + N + 1, e = c + 1;
            q[0] = a; q[1] = c; q[2] = b; q[3] = b; q[4] = c; q[5] = e;
        }
    const uint32_t bad_idx[3] = {0, 1, 100000};
    CHECK(tw_tileset_add_mesh(ts, pos, NULL, (N + 1) * (N + 1), bad_idx, 1) == TW_ERR_INVALID);
    const float nan_pos[9] = {0, 0, 0, NAN, 0, 0, 0, 1, 0};
    const uint32_t tri[3] = {0, 1, 2};
    CHECK(tw_tileset_add_mesh(ts, nan_pos, NULL, 3, tri, 1) == TW_ERR_INVALID);
    const int mesh = tw_tileset_add_mesh(ts, pos, NULL, (N + 1) * (N + 1), idx, 2 * N * N);
    CHECK(mesh == 0);
    const int mat = tw_tileset_add_material(ts, (const float[4]){0.5f, 0.5f, 0.5f, 1});
    CHECK(tw_tileset_finish(ts, 100) == TW_ERR_INVALID);   /* no prototype yet */
    const int p0 = tw_tileset_add_prototype(ts, "a", 1.0f);
    CHECK(tw_tileset_add_prototype(ts, "bad", 0.0f) == TW_ERR_INVALID);
    CHECK(tw_tileset_add_instance(ts, (uint32_t)p0, 5, (uint32_t)mat, NULL) == TW_ERR_INVALID);
    /* Rotated 90 degrees about y and moved. */
    const float rot[12] = {0, 0, 1, 2, 0, 1, 0, 0, -1, 0, 0, 17};
    CHECK(tw_tileset_add_instance(ts, (uint32_t)p0, (uint32_t)mesh, (uint32_t)mat, rot) == 0);
    CHECK(tw_tileset_add_instance(ts, (uint32_t)p0, (uint32_t)mesh, (uint32_t)mat, NULL) == 1);
    CHECK(tw_tileset_finish(ts, 100) == TW_OK);
    CHECK(tw_tileset_add_prototype(ts, "late", 1.0f) == TW_ERR_INVALID);

    const struct tw_mesh *m = &ts->meshes[0];
    CHECK(m->part_count >= 18);
    /* Parts tile the index range in order, each at most 100 triangles. */
    uint32_t next = 0;
    for (uint32_t k = m->first_part; k < m->first_part + m->part_count; k++) {
        CHECK(ts->parts[k].first_triangle == next);
        CHECK(ts->parts[k].triangle_count <= 100 && ts->parts[k].triangle_count > 0);
        next += ts->parts[k].triangle_count;
    }
    CHECK(next == m->triangle_count);
    /* The reordering permutes triangles: the multiset of (sorted) triangles is kept. */
    uint64_t sum_before = 0, sum_after = 0;
    for (uint32_t t = 0; t < 2 * N * N; t++)
        sum_before += (uint64_t)(idx[3 * t] + 1) * (idx[3 * t + 1] + 7) * (idx[3 * t + 2] + 13);
    for (uint32_t t = 0; t < m->triangle_count; t++)
        sum_after += (uint64_t)(m->indices[3 * t] + 1) * (m->indices[3 * t + 1] + 7) *
                     (m->indices[3 * t + 2] + 13);
    CHECK(sum_before == sum_after);
    /* Every cluster box holds its triangles, transformed; the common box holds all. */
    const struct tw_prototype *proto = &ts->prototypes[0];
    CHECK(proto->cluster_count == 2 * m->part_count);
    CHECK(proto->triangle_count == 2ull * m->triangle_count);
    for (uint32_t c = 0; c < proto->cluster_count; c++) {
        const struct tw_cluster *cl = &proto->clusters[c];
        const struct tw_instance *in = &proto->instances[cl->instance];
        const struct tw_mesh_part *part = &ts->parts[cl->part];
        for (uint32_t t = part->first_triangle; t < part->first_triangle + part->triangle_count; t++)
            for (int v = 0; v < 3; v++) {
                const float *p = m->positions + 3 * m->indices[3 * t + v];
                const float *x = in->transform;
                const float q[3] = {x[0] * p[0] + x[1] * p[1] + x[2] * p[2] + x[3],
                                    x[4] * p[0] + x[5] * p[1] + x[6] * p[2] + x[7],
                                    x[8] * p[0] + x[9] * p[1] + x[10] * p[2] + x[11]};
                for (int a = 0; a < 3; a++) {
                    CHECK(q[a] >= cl->box.min[a] && q[a] <= cl->box.max[a]);
                    CHECK(q[a] >= ts->common_box.min[a] && q[a] <= ts->common_box.max[a]);
                }
            }
    }
    /* The rotated instance spans x in [2, 2 + 15] and z in [17 - 15, 17]. */
    CHECK(fabsf(proto->instances[0].box.min[0] - 2.0f) < 1e-5f);
    CHECK(fabsf(proto->instances[0].box.max[2] - 17.0f) < 1e-5f);
    CHECK(fabsf(proto->instances[0].box.min[2] - 2.0f) < 1e-5f);
    free(pos);
    free(idx);
    tw_tileset_destroy(ts);
    tw_tileset_destroy(NULL);
}

static void test_boxes(void)
{
    struct tw_box b = tw_box_empty();
    CHECK(tw_box_is_empty(&b));
    CHECK(tw_box_surface_area(&b) == 0.0f);
    tw_box_add_point(&b, (const float[3]){1, 2, 3});
    tw_box_add_point(&b, (const float[3]){2, 4, 6});
    CHECK(!tw_box_is_empty(&b));
    CHECK(tw_box_surface_area(&b) == 2.0f * (1 * 2 + 2 * 3 + 3 * 1));
    CHECK(tw_box_distance2(&b, (const float[3]){1.5f, 3, 4}) == 0.0f);
    CHECK(tw_box_distance2(&b, (const float[3]){0, 2, 3}) == 1.0f);
    CHECK(tw_box_distance2(&b, (const float[3]){5, 8, 6}) == 9.0f + 16.0f);
}

/* The cell map against a naive list, with random inserts and removals. */
static void test_cell_map(void)
{
    struct tw_cell_map *m = NULL;
    CHECK(tw_cell_map_create(&m) == TW_OK);
    enum { N = 600 };
    static struct tw_cell cells[N];
    static uint64_t values[N];
    static bool present[N];
    for (int k = 0; k < N; k++) {
        cells[k].i = (int64_t)(next_random() % 40) - 20 + (k % 3 == 0 ? ((int64_t)1 << 61) : 0);
        cells[k].j = (int64_t)k - 300;
    }
    for (int round = 0; round < 20000; round++) {
        const int k = (int)(next_random() % N);
        if (next_random() % 3 == 0) {
            CHECK(tw_cell_map_remove(m, cells[k]) == present[k]);
            present[k] = false;
        } else {
            values[k] = next_random();
            CHECK(tw_cell_map_set(m, cells[k], values[k]) == TW_OK);
            present[k] = true;
        }
        if (round % 1000 == 0) {
            size_t count = 0;
            for (int q = 0; q < N; q++) {
                const uint64_t *v = tw_cell_map_find(m, cells[q]);
                CHECK((v != NULL) == present[q]);
                if (v && present[q])
                    CHECK(*v == values[q]);
                count += present[q];
            }
            CHECK(tw_cell_map_count(m) == count);
        }
    }
    tw_cell_map_clear(m);
    CHECK(tw_cell_map_count(m) == 0);
    CHECK(tw_cell_map_find(m, cells[0]) == NULL);
    tw_cell_map_destroy(m);
}

static void test_tile_cache(void)
{
    struct tw_tile_cache *c = NULL;
    CHECK(tw_tile_cache_create(3, &c) == TW_OK);
    if (!c)
        return;
    struct tw_tile_handle a, b, again;
    bool created = false;
    CHECK(tw_tile_cache_acquire(c, (struct tw_cell){5, 6}, 2, 100, 1, &a, &created) == TW_OK);
    CHECK(created);
    unsigned char *state = tw_tile_cache_state(c, a);
    CHECK(state != NULL && state[0] == 0 && state[99] == 0);
    state[7] = 42;
    CHECK(tw_tile_cache_acquire(c, (struct tw_cell){5, 6}, 2, 100, 2, &again, &created) == TW_OK);
    CHECK(!created && again.slot == a.slot && again.generation == a.generation);
    CHECK(((unsigned char *)tw_tile_cache_state(c, again))[7] == 42);  /* state survives */
    CHECK(tw_tile_cache_acquire(c, (struct tw_cell){-1, 0}, 0, 50, 2, &b, &created) == TW_OK);
    CHECK(tw_tile_cache_count(c) == 2);
    const uint64_t bytes2 = tw_tile_cache_bytes(c);
    /* Seen at frame 2, evict_after 3: kept through frame 5, gone at frame 6. */
    CHECK(tw_tile_cache_evict(c, 5) == 0);
    CHECK(tw_tile_cache_acquire(c, (struct tw_cell){-1, 0}, 0, 50, 5, &b, &created) == TW_OK);
    CHECK(!created);
    CHECK(tw_tile_cache_evict(c, 6) == 1);
    CHECK(!tw_tile_cache_alive(c, a));
    CHECK(tw_tile_cache_state(c, a) == NULL);       /* the kept handle reads as stale */
    CHECK(tw_tile_cache_info(c, a) == NULL);
    CHECK(tw_tile_cache_alive(c, b));
    CHECK(tw_tile_cache_bytes(c) == bytes2 - 100);  /* exact accounting */
    struct tw_tile_handle found;
    CHECK(!tw_tile_cache_find(c, (struct tw_cell){5, 6}, &found));
    /* The slot is reused, and the old handle still does not match it. */
    struct tw_tile_handle d;
    CHECK(tw_tile_cache_acquire(c, (struct tw_cell){9, 9}, 1, 10, 7, &d, &created) == TW_OK);
    CHECK(created && d.slot == a.slot && d.generation != a.generation);
    CHECK(tw_tile_cache_state(c, a) == NULL);
    const struct tw_tile_handle packed = tw_tile_handle_unpack(tw_tile_handle_pack(d));
    CHECK(packed.slot == d.slot && packed.generation == d.generation);
    const struct tw_tile_info *info = tw_tile_cache_info(c, d);
    CHECK(info && info->cell.i == 9 && info->prototype == 1 && info->created_frame == 7);
    struct tw_tile_handle zero = {0, 0};
    CHECK(!tw_tile_cache_alive(c, zero));
    tw_tile_cache_destroy(c);
    tw_tile_cache_destroy(NULL);
}

/* ---- hostile input ------------------------------------------------ */

static void capture_last(void *user, enum tw_log_level level, const char *msg)
{
    (void)level;
    snprintf((char *)user, 256, "%s", msg);
}

/* Class 5: control characters never reach a terminal. */
static void test_escape(void)
{
    char out[256];
    CHECK(strcmp(tw_log_escape("plain text, \\ and \"quotes\"", out, sizeof(out)),
                 "plain text, \\ and \"quotes\"") == 0);
    CHECK(strcmp(tw_log_escape("a\x1b[2J\nb\r\tc\x7f", out, sizeof(out)),
                 "a\\x1b[2J\\nb\\r\\tc\\x7f") == 0);
    /* UTF-8 is kept; C1 controls (U+009B is CSI), bidi overrides and broken
     * sequences are not. */
    CHECK(strcmp(tw_log_escape("caf\xc3\xa9 \xe2\x82\xac", out, sizeof(out)),
                 "caf\xc3\xa9 \xe2\x82\xac") == 0);
    CHECK(strcmp(tw_log_escape("\xc2\x9b" "2J", out, sizeof(out)), "\\u009b2J") == 0);
    CHECK(strcmp(tw_log_escape("x\xe2\x80\xaey", out, sizeof(out)), "x\\u202ey") == 0);
    CHECK(strcmp(tw_log_escape("\x9b\xff\xc3", out, sizeof(out)), "\\x9b\\xff\\xc3") == 0);
    CHECK(strcmp(tw_log_escape("\xc0\xaf\xed\xa0\x80", out, sizeof(out)),
                 "\\xc0\\xaf\\xed\\xa0\\x80") == 0); /* overlong, surrogate */
    CHECK(strcmp(tw_log_escape_bytes("a\0b", 3, out, sizeof(out)), "a\\x00b") == 0);
    CHECK(strcmp(tw_log_escape(NULL, out, sizeof(out)), "") == 0);
    /* Idempotent. */
    char twice[256];
    tw_log_escape("k\x1b]0;pwned\x07\n", out, sizeof(out));
    CHECK(strcmp(tw_log_escape(out, twice, sizeof(twice)), out) == 0);
    /* Cut at a piece boundary, with "...". */
    char small[8];
    CHECK(strcmp(tw_log_escape("abcdefg", small, sizeof(small)), "abcdefg") == 0);
    CHECK(strcmp(tw_log_escape("abcdefgh", small, sizeof(small)), "abcd...") == 0);
    CHECK(strcmp(tw_log_escape("\x1b\x1b\x1b", small, sizeof(small)), "\\x1b...") == 0);
    char tiny[3];
    CHECK(strcmp(tw_log_escape("abcdef", tiny, sizeof(tiny)), "..") == 0);
    /* The logger escapes every message. */
    char last[256] = "";
    const struct tw_log log = {capture_last, last};
    tw_log_printf(&log, TW_LOG_ERROR, "key \"%s\": unknown", "\x1b[2J\nforged: ok");
    CHECK(strcmp(last, "key \"\\x1b[2J\\nforged: ok\": unknown") == 0);
    CHECK(!strchr(last, '\n') && !strchr(last, '\x1b'));
    /* The reversible form: the same, and a backslash doubled, so that a
     * backslash of the text is told from an escape. */
    CHECK(strcmp(tw_log_escape_reversible("a\\x1b\x1b", out, sizeof(out)), "a\\\\x1b\\x1b") == 0);
    CHECK(strcmp(tw_log_escape_reversible("x\xe2\x80\xae\xc2\x9b\xff\\", out, sizeof(out)),
                 "x\\u202e\\u009b\\xff\\\\") == 0);
    CHECK(strcmp(tw_log_escape_reversible("caf\xc3\xa9\n", out, sizeof(out)),
                 "caf\xc3\xa9\\n") == 0);
    CHECK(strcmp(tw_log_escape_reversible("abc\\def", small, sizeof(small)), "abc...") == 0);
    CHECK(strcmp(tw_log_escape_reversible(NULL, out, sizeof(out)), "") == 0);
}

/* Whether a mesh holds triangle (a, b, c), its corners in that order. */
static bool has_triangle(const struct tw_mesh *m, uint32_t a, uint32_t b, uint32_t c)
{
    for (uint32_t t = 0; t < m->triangle_count; t++) {
        const uint32_t *i = m->indices + 3 * (size_t)t;
        if (i[0] == a && i[1] == b && i[2] == c)
            return true;
    }
    return false;
}

/* Finishing drops the triangles that cover nothing (collinear or coincident
 * corners, or a height within float rounding of the longest edge), which a
 * rasteriser may still give a stray fragment at any depth (the near plane,
 * on kenney-city); a thin triangle that does have an area stays. */
static void test_triangles_without_area(void)
{
    const float pos[] = {
        0, 0, 0,   1, 0, 0,   0, 1, 0,   1, 1, 0,   /* 0-3: a unit quad */
        2, 0, 0,   3, 0, 0,                         /* 4-5: on the line of 1 */
        0, 0, 0,                                    /* 6: where 0 is */
        0.5f, 5e-8f, 0,                             /* 7: 5e-8 above the edge 0-1 */
        0.5f, 1e-6f, 0,                             /* 8: 1e-6 above it */
        31.5f, 9.25f, 10.5f, 31.5f, 9.25f, 18.3010883f, 31.5f, 9.25f, 11.6989126f,
    };                                              /* 9-11: kenney-city's filler */
    const uint32_t idx[] = {0, 1, 2, 1, 3, 2, 1, 4, 5, 0, 6, 2, 0, 1, 7,
                            0, 1, 8, 9, 10, 11, 2, 2, 2};
    enum { VERTICES = 12, TRIANGLES = 8, KEPT = 3 };
    const float grey[4] = {0.5f, 0.5f, 0.5f, 1};
    const float moved[12] = {1, 0, 0, 5, 0, 1, 0, 0, 0, 0, 1, 5};
    /* Unsplit and unmerged (0), then merged (64): instances under 64
     * triangles are baked into one mesh. */
    for (uint32_t max_tris = 0; max_tris <= 64; max_tris += 64) {
        struct tw_tileset *ts = NULL;
        CHECK(tw_tileset_create("t", 10.0f, 10.0f, &ts) == TW_OK);
        if (!ts)
            return;
        CHECK(tw_tileset_add_mesh(ts, pos, NULL, VERTICES, idx, TRIANGLES) == 0);
        CHECK(tw_tileset_add_material(ts, grey) == 0);
        CHECK(tw_tileset_add_prototype(ts, "p", 1.0f) == 0);
        CHECK(tw_tileset_add_instance(ts, 0, 0, 0, NULL) == 0);
        CHECK(tw_tileset_add_instance(ts, 0, 0, 0, moved) == 1);
        CHECK(tw_tileset_finish(ts, max_tris) == TW_OK);
        const struct tw_mesh *m = &ts->meshes[0];
        CHECK_MSG(m->triangle_count == KEPT, "%u triangles kept", m->triangle_count);
        CHECK(has_triangle(m, 0, 1, 2) && has_triangle(m, 1, 3, 2) && has_triangle(m, 0, 1, 8));
        const struct tw_prototype *p = &ts->prototypes[0];
        CHECK_MSG(p->triangle_count == 2 * KEPT, "prototype: %llu triangles",
                  (unsigned long long)p->triangle_count);
        uint64_t in_clusters = 0;
        for (uint32_t c = 0; c < p->cluster_count; c++)
            in_clusters += p->clusters[c].triangle_count;
        CHECK(in_clusters == 2 * KEPT);
        if (max_tris > 0) {
            CHECK_MSG(ts->mesh_count == 2 && ts->meshes[1].triangle_count == 2 * KEPT,
                      "%u meshes, the merged one of %u triangles", ts->mesh_count,
                      ts->mesh_count > 1 ? ts->meshes[1].triangle_count : 0);
        }
        tw_tileset_destroy(ts);
    }

    /* A mesh with no triangle left has no cluster and an empty box; a
     * prototype with nothing else is as empty as one with no instance. */
    const uint32_t fillers[] = {1, 4, 5, 9, 10, 11};
    for (int alone = 0; alone < 2; alone++) {
        struct tw_tileset *ts = NULL;
        CHECK(tw_tileset_create("t", 10.0f, 10.0f, &ts) == TW_OK);
        if (!ts)
            return;
        CHECK(tw_tileset_add_mesh(ts, pos, NULL, VERTICES, fillers, 2) == 0);
        CHECK(tw_tileset_add_mesh(ts, pos, NULL, VERTICES, idx, 2) == 1);
        CHECK(tw_tileset_add_material(ts, grey) == 0);
        CHECK(tw_tileset_add_prototype(ts, "p", 1.0f) == 0);
        CHECK(tw_tileset_add_instance(ts, 0, 0, 0, NULL) == 0);
        if (!alone)
            CHECK(tw_tileset_add_instance(ts, 0, 1, 0, moved) == 1);
        const int err = tw_tileset_finish(ts, 64);
        if (alone) {
            CHECK_MSG(err == TW_ERR_INVALID, "only triangles without area: %d", err);
        } else {
            CHECK(err == TW_OK);
            const struct tw_prototype *p = &ts->prototypes[0];
            CHECK(ts->meshes[0].triangle_count == 0 && ts->meshes[0].part_count == 0);
            CHECK(p->cluster_count == 1 && p->clusters[0].instance == 1);
            CHECK(p->triangle_count == 2 && tw_box_is_empty(&p->instances[0].box));
            CHECK(p->box.min[0] == 5.0f && p->box.max[0] == 6.0f);
        }
        tw_tileset_destroy(ts);
    }
}

/* A tileset of two prototypes over three meshes, the small ones merged. */
static struct tw_tileset *sample_tileset(void)
{
    const float pos[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0, 0, 0, 1, 1, 0, 1};
    const uint32_t idx[] = {0, 1, 2, 1, 3, 2, 0, 4, 1, 1, 4, 5};
    const float grey[4] = {0.5f, 0.5f, 0.5f, 1}, red[4] = {1, 0, 0, 1};
    struct tw_tileset *ts = NULL;
    if (tw_tileset_create("sample", 10.0f, 10.0f, &ts) != TW_OK)
        return NULL;
    int ok = tw_tileset_add_mesh(ts, pos, NULL, 6, idx, 4) == 0 &&
             tw_tileset_add_mesh(ts, pos, NULL, 4, idx, 2) == 1 &&
             tw_tileset_add_mesh(ts, pos, NULL, 6, idx + 6, 2) == 2 &&
             tw_tileset_add_material(ts, grey) == 0 && tw_tileset_add_material(ts, red) == 1 &&
             tw_tileset_add_prototype(ts, "a", 1.0f) == 0 &&
             tw_tileset_add_prototype(ts, "b", 2.0f) == 1;
    for (uint32_t k = 0; ok && k < 12; k++) {
        const float at[12] = {1, 0, 0, (float)(k % 4) * 2, 0, 1, 0, 0, 0, 0, 1, (float)(k / 4) * 2};
        ok = tw_tileset_add_instance(ts, k % 2, k % 3, k % 2, at) >= 0;
    }
    if (!ok || tw_tileset_finish(ts, 3) != TW_OK) {
        tw_tileset_destroy(ts);
        return NULL;
    }
    return ts;
}

/* tw_tileset_pack(): the same tileset in one block, bytes the block's. */
static void test_pack(void)
{
    struct tw_tileset *a = sample_tileset(), *b = sample_tileset();
    CHECK(a && b);
    if (!a || !b)
        goto out;
    struct tw_tileset *old = b;
    const uint64_t unpacked = tw_tileset_bytes(b);
    CHECK(tw_tileset_pack(&b) == TW_OK && b != old);
    CHECK_MSG(tw_tileset_bytes(b) <= unpacked + 16 * 64 && tw_tileset_bytes(b) > 0,
              "packed %llu bytes, unpacked %llu", (unsigned long long)tw_tileset_bytes(b),
              (unsigned long long)unpacked);
    CHECK(b->finished && strcmp(b->name, "sample") == 0 && b->mesh_count == a->mesh_count &&
          b->part_count == a->part_count && b->material_count == a->material_count &&
          b->prototype_count == a->prototype_count && a->mesh_count > 3);
    CHECK(memcmp(b->materials, a->materials, sizeof(*a->materials) * a->material_count) == 0);
    CHECK(memcmp(b->parts, a->parts, sizeof(*a->parts) * a->part_count) == 0);
    uint32_t colored = 0;
    for (uint32_t k = 0; k < a->mesh_count && k < b->mesh_count; k++) {
        const struct tw_mesh *ma = &a->meshes[k], *mb = &b->meshes[k];
        CHECK_MSG(mb->vertex_count == ma->vertex_count &&
                  mb->triangle_count == ma->triangle_count &&
                  memcmp(mb->positions, ma->positions, 12 * (size_t)ma->vertex_count) == 0 &&
                  memcmp(mb->normals, ma->normals, 12 * (size_t)ma->vertex_count) == 0 &&
                  memcmp(mb->indices, ma->indices, 12 * (size_t)ma->triangle_count) == 0 &&
                  !ma->colors == !mb->colors &&
                  (!ma->colors || memcmp(mb->colors, ma->colors, 4 * (size_t)ma->vertex_count) == 0),
                  "mesh %u differs", k);
        colored += ma->colors != NULL;
        /* Every array lies inside the block. */
        const char *lo = (const char *)b, *hi = lo + tw_tileset_bytes(b);
        CHECK((const char *)mb->positions > lo && (const char *)mb->indices < hi);
    }
    CHECK_MSG(colored == 2, "%u merged meshes with colours", colored);
    for (uint32_t p = 0; p < a->prototype_count && p < b->prototype_count; p++) {
        const struct tw_prototype *pa = &a->prototypes[p], *pb = &b->prototypes[p];
        CHECK_MSG(pb->instance_count == pa->instance_count &&
                  pb->cluster_count == pa->cluster_count &&
                  pb->triangle_count == pa->triangle_count &&
                  memcmp(pb->instances, pa->instances,
                         sizeof(*pa->instances) * pa->instance_count) == 0 &&
                  memcmp(pb->clusters, pa->clusters, sizeof(*pa->clusters) * pa->cluster_count) == 0,
                  "prototype %u differs", p);
    }
    /* A packed tileset packs again; an unfinished one does not. */
    CHECK(tw_tileset_pack(&b) == TW_OK && b->mesh_count == a->mesh_count);
    struct tw_tileset *raw = NULL;
    CHECK(tw_tileset_create("raw", 1.0f, 1.0f, &raw) == TW_OK);
    struct tw_tileset *before = raw;
    CHECK(tw_tileset_pack(&raw) == TW_ERR_INVALID && raw == before);
    CHECK(tw_tileset_pack(NULL) == TW_ERR_INVALID);
    tw_tileset_destroy(raw);
out:
    tw_tileset_destroy(a);
    tw_tileset_destroy(b);
}

/* Packed blocks of 64 KiB or more are anonymous mappings of their own, whole
 * pages, unmapped when freed (so a freed tile's memory goes back to the
 * system whatever malloc keeps); smaller ones are malloc's. msync() answers
 * ENOMEM for a range that is not mapped. */
static void test_pack_pages(void)
{
    const long page_size = sysconf(_SC_PAGESIZE);
    CHECK(page_size > 0);
    const size_t page = page_size > 0 ? (size_t)page_size : 4096u;
    const size_t sizes[] = {1, 4096, TW_PAGES_MAP_MIN - 1, TW_PAGES_MAP_MIN,
                            TW_PAGES_MAP_MIN + 1, 3 * TW_PAGES_MAP_MIN + 17};
    for (size_t k = 0; k < sizeof(sizes) / sizeof(sizes[0]); k++) {
        const size_t n = sizes[k];
        unsigned char *block = tw_pages_alloc(n);
        CHECK_MSG(block && (uintptr_t)block % 16 == 0, "a block of %zu bytes", n);
        if (!block)
            continue;
        memset(block, 0xa5, n);
        CHECK(block[0] == 0xa5 && block[n - 1] == 0xa5);
        const bool mapped = n >= TW_PAGES_MAP_MIN;
        CHECK_MSG(!mapped || (uintptr_t)block % page == 0, "%zu bytes: not page-aligned", n);
        const size_t length = (n + page - 1) / page * page;
        if (mapped)
            CHECK(msync(block, length, MS_ASYNC) == 0);
        tw_pages_free(block, n);
        if (mapped) {
            errno = 0;
            CHECK_MSG(msync(block, length, MS_ASYNC) == -1 && errno == ENOMEM,
                      "%zu bytes: still mapped after tw_pages_free()", n);
        }
    }
    tw_pages_free(NULL, 0);
    tw_pages_free(NULL, TW_PAGES_MAP_MIN);

    /* A tileset whose block is mapped: the same content, destroyed by unmapping. */
    enum { GRID = 64 };   /* 64 x 64 vertices: about 100 KiB of positions and normals */
    float *pos = malloc(sizeof(float) * 3 * GRID * GRID);
    uint32_t *idx = malloc(sizeof(uint32_t) * 6 * (GRID - 1) * (GRID - 1));
    struct tw_tileset *ts = NULL;
    CHECK(pos && idx && tw_tileset_create("big", 100.0f, 100.0f, &ts) == TW_OK);
    if (!pos || !idx || !ts)
        goto out;
    for (uint32_t j = 0; j < GRID; j++)
        for (uint32_t i = 0; i < GRID; i++) {
            float *v = &pos[3 * (j * GRID + i)];
            v[0] = (float)i;
            v[1] = (float)((i * 7 + j * 3) % 5) * 0.25f;
            v[2] = (float)j;
        }
    uint32_t t = 0;
    for (uint32_t j = 0; j + 1 < GRID; j++)
        for (uint32_t i = 0; i + 1 < GRID; i++) {
            const uint32_t a = j * GRID + i;
            const uint32_t quad[6] = {a, a + GRID, a + 1, a + 1, a + GRID, a + GRID + 1};
            memcpy(&idx[6 * t++], quad, sizeof(quad));
        }
    const float grey[4] = {0.5f, 0.5f, 0.5f, 1};
    CHECK(tw_tileset_add_mesh(ts, pos, NULL, GRID * GRID, idx, 2 * t) == 0 &&
          tw_tileset_add_material(ts, grey) == 0 && tw_tileset_add_prototype(ts, "p", 1.0f) == 0 &&
          tw_tileset_add_instance(ts, 0, 0, 0, NULL) == 0 && tw_tileset_finish(ts, 256) == TW_OK);
    const uint32_t triangles = ts->finished ? ts->prototypes[0].triangle_count : 0;
    CHECK(tw_tileset_pack(&ts) == TW_OK);
    const uint64_t bytes = tw_tileset_bytes(ts);
    CHECK_MSG(bytes >= TW_PAGES_MAP_MIN && (uintptr_t)ts % page == 0,
              "a packed tileset of %llu bytes, at %p", (unsigned long long)bytes, (void *)ts);
    CHECK(ts->prototypes[0].triangle_count == triangles && triangles == 2 * t &&
          ts->meshes[0].vertex_count == GRID * GRID &&
          memcmp(ts->meshes[0].positions, pos, sizeof(float) * 3 * GRID * GRID) == 0);
    /* Packed again: a new mapping, the old one unmapped. */
    void *old = ts;
    const size_t old_length = ((size_t)bytes + page - 1) / page * page;
    CHECK(tw_tileset_pack(&ts) == TW_OK && (void *)ts != old);
    errno = 0;
    CHECK(msync(old, old_length, MS_ASYNC) == -1 && errno == ENOMEM);
    CHECK(ts->meshes[0].vertex_count == GRID * GRID &&
          memcmp(ts->meshes[0].positions, pos, sizeof(float) * 3 * GRID * GRID) == 0);
out:
    tw_tileset_destroy(ts);
    free(pos);
    free(idx);
}

/* Classes 1 and 3: the builder refuses out-of-range content, the cell math
 * never converts an out-of-range value to an integer. */
static void test_limits(void)
{
    struct tw_tileset *ts = NULL;
    CHECK(tw_tileset_create("t", 10.0f, 10.0f, &ts) == TW_OK);
    if (!ts)
        return;
    const uint32_t tri[3] = {0, 1, 2};
    const float far_mesh[9] = {0, 0, 0, 1, 0, 0, 0, 3e38f, 0};
    CHECK(tw_tileset_add_mesh(ts, far_mesh, NULL, 3, tri, 1) == TW_ERR_LIMIT);
    const float mm_mesh[9] = {0, 0, 0, 5000, 0, 0, 0, 5000, 0};   /* 5 m in millimetres */
    const int mesh = tw_tileset_add_mesh(ts, mm_mesh, NULL, 3, tri, 1);
    CHECK(mesh == 0);
    const int mat = tw_tileset_add_material(ts, (const float[4]){1, 1, 1, 1});
    const int p = tw_tileset_add_prototype(ts, "p", 1.0f);
    const float huge_move[12] = {1, 0, 0, 3.4e38f, 0, 1, 0, 0, 0, 0, 1, 0};
    CHECK(tw_tileset_add_instance(ts, (uint32_t)p, (uint32_t)mesh, (uint32_t)mat, huge_move) ==
          TW_ERR_LIMIT);
    const float huge_scale[12] = {1e30f, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    CHECK(tw_tileset_add_instance(ts, (uint32_t)p, (uint32_t)mesh, (uint32_t)mat, huge_scale) ==
          TW_ERR_LIMIT);
    /* Unscaled, the millimetre mesh reaches 5 km: within reach, but it spans
     * 500 footprints. */
    CHECK(tw_tileset_add_instance(ts, (uint32_t)p, (uint32_t)mesh, (uint32_t)mat, NULL) == 0);
    const float scale_1e2[12] = {100, 0, 0, 0, 0, 100, 0, 0, 0, 0, 100, 0};
    CHECK(tw_tileset_add_instance(ts, (uint32_t)p, (uint32_t)mesh, (uint32_t)mat, scale_1e2) ==
          TW_ERR_LIMIT);  /* 500 km */
    CHECK(tw_tileset_finish(ts, 0) == TW_ERR_LIMIT);
    tw_tileset_destroy(ts);
    ts = NULL;
    CHECK(tw_tileset_create("t", 10.0f, 10.0f, &ts) == TW_OK);
    const float mm[12] = {0.001f, 0, 0, 1, 0, 0.001f, 0, 0, 0, 0, 0.001f, 1};
    CHECK(tw_tileset_add_mesh(ts, mm_mesh, NULL, 3, tri, 1) == 0);
    CHECK(tw_tileset_add_material(ts, (const float[4]){1, 1, 1, 1}) == 0);
    CHECK(tw_tileset_add_prototype(ts, "p", 1.0f) == 0);
    CHECK(tw_tileset_add_instance(ts, 0, 0, 0, mm) == 0);
    CHECK(tw_tileset_finish(ts, 0) == TW_OK);
    CHECK(fabsf(ts->common_box.max[0] - 6.0f) < 1e-4f);
    CHECK(tw_tiles_cells_in_reach(&ts->common_box, 10, 10, 600) < 200 * 200);
    tw_tileset_destroy(ts);

    /* Normalising: bad footprints and huge offsets are refused, not
     * converted. */
    struct tw_world_pos pos = {{0, 0}, {5, 1, 5}};
    CHECK(tw_tiles_normalize(&pos, INFINITY, 10) == TW_ERR_INVALID);
    CHECK(tw_tiles_normalize(&pos, 1e-30f, 1e-30f) == TW_ERR_INVALID);   /* 5e30 cells */
    CHECK(tw_tiles_normalize(&pos, 1e-38f, 10) == TW_ERR_INVALID);
    CHECK(pos.local[0] == 5 && pos.cell.i == 0);
    struct tw_world_pos near_edge = {{INT64_MAX - 1, 0}, {30, 0, 0}};
    CHECK(tw_tiles_normalize(&near_edge, 10, 10) == TW_ERR_INVALID);
    const double far[3] = {1e15 + 12.5, -3.0, -25.0};
    struct tw_world_pos out;
    CHECK(tw_tiles_normalize_double((struct tw_cell){2, 3}, far, 10, 10, &out) == TW_OK);
    CHECK(out.cell.i == 2 + 100000000000001ll && out.cell.j == 3 - 3);
    CHECK(out.local[0] == 2.5f && out.local[1] == -3.0f &&
          fabsf(out.local[2] - 5.0f) < 1e-6f);
    const double huge[3] = {1e300, 0, 0};
    CHECK(tw_tiles_normalize_double((struct tw_cell){0, 0}, huge, 10, 10, &out) ==
          TW_ERR_INVALID);
    const double high[3] = {0, 1e300, 0};
    CHECK(tw_tiles_normalize_double((struct tw_cell){0, 0}, high, 10, 10, &out) ==
          TW_ERR_INVALID);

    /* The cells a frame must consider. */
    const struct tw_box cb = {{0, 0, 0}, {80, 50, 80}};
    const double reach = tw_tiles_cells_in_reach(&cb, 80, 80, 600);
    CHECK(reach > 15 * 15 && reach < 20 * 20);
    CHECK(tw_tiles_cells_in_reach(&cb, 0.01f, 0.01f, 600) > TW_TILES_MAX_CELLS_IN_VIEW);
    CHECK(tw_tiles_cells_in_reach(&cb, 1e-45f, 1e-45f, 600) > 1e90);
    CHECK(isinf(tw_tiles_cells_in_reach(&cb, 0, 80, 600)));
}

int main(void)
{
    test_escape();
    test_limits();
    test_cell_map();
    test_tile_cache();
    test_floor_div_mod();
    test_normalize_round_trip();
    test_boxes();
    test_selection();
    test_tileset_builder();
    test_triangles_without_area();
    test_pack();
    test_pack_pages();
    return check_summary("test-tiles");
}
