/*
 * Moving objects (runtime.h, tw_world_object_*): cars driving the city's
 * streets, balloons above its roofs and a wall carried in front of the
 * camera, seen by every culling method.
 *  - No method misses a pixel of them (the oracle's count, --verify), the
 *    balloons included, which lie above every tile's box: the common box
 *    that tile queries draw grows to hold them.
 *  - They occlude: with the wall in front of the camera, tilequery+chc
 *    draws a fraction of what it draws without.
 *  - They are drawn: images with objects differ from images without.
 *  - Moving within their cells keeps the cells' culling state (a refit: no
 *    BVH built afresh, no tile instance made afresh); moving apart until
 *    the refitted BVH is worn down builds it afresh.
 *  - Misuse is refused with the documented errors.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tests/check.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

enum { W = 192, H = 108, FRAMES = 16, CARS = 240, BALLOONS = 24 };
enum { CAR = 0, BALLOON = 1, WALL = 2 };

static void log_quiet(void *user, enum tw_log_level level, const char *msg)
{
    (void)user;
    if (level <= TW_LOG_WARN && !getenv("TEST_OBJECTS_QUIET"))
        fprintf(stderr, "log: %s\n", msg);
}

/* A box mesh sx x sy x sz standing on y = y0, centred on x = z = 0. */
static int add_box(struct tw_tileset *ts, uint32_t proto, uint32_t material, float sx, float sy,
                   float sz, float y0)
{
    const float x = sx / 2, z = sz / 2, y1 = y0 + sy;
    /* Four vertices per face, flat normals. */
    const float face[6][4][3] = {
        {{-x, y0, z}, {x, y0, z}, {x, y1, z}, {-x, y1, z}},       /* +z */
        {{x, y0, -z}, {-x, y0, -z}, {-x, y1, -z}, {x, y1, -z}},   /* -z */
        {{x, y0, z}, {x, y0, -z}, {x, y1, -z}, {x, y1, z}},       /* +x */
        {{-x, y0, -z}, {-x, y0, z}, {-x, y1, z}, {-x, y1, -z}},   /* -x */
        {{-x, y1, z}, {x, y1, z}, {x, y1, -z}, {-x, y1, -z}},     /* +y */
        {{-x, y0, -z}, {x, y0, -z}, {x, y0, z}, {-x, y0, z}},     /* -y */
    };
    const float normal[6][3] = {{0, 0, 1}, {0, 0, -1}, {1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}};
    float pos[72], nrm[72];
    uint32_t idx[36];
    for (int f = 0; f < 6; f++) {
        for (int v = 0; v < 4; v++)
            for (int a = 0; a < 3; a++) {
                pos[(f * 4 + v) * 3 + a] = face[f][v][a];
                nrm[(f * 4 + v) * 3 + a] = normal[f][a];
            }
        const uint32_t b = (uint32_t)f * 4;
        const uint32_t q[6] = {b, b + 1, b + 2, b, b + 2, b + 3};
        memcpy(idx + f * 6, q, sizeof(q));
    }
    const int mesh = tw_tileset_add_mesh(ts, pos, nrm, 24, idx, 12);
    if (mesh < 0)
        return mesh;
    const int in = tw_tileset_add_instance(ts, proto, (uint32_t)mesh, material, NULL);
    return in < 0 ? in : TW_OK;
}

/* The models: a car (body and cabin), a balloon, a wall. */
static struct tw_tileset *make_models(void)
{
    struct tw_tileset *ts = NULL;
    if (tw_tileset_create("objects", 80.0f, 80.0f, &ts) != TW_OK)
        return NULL;
    const float red[4] = {0.8f, 0.1f, 0.1f, 1}, glass[4] = {0.2f, 0.3f, 0.4f, 1},
                yellow[4] = {0.9f, 0.8f, 0.1f, 1}, grey[4] = {0.5f, 0.5f, 0.55f, 1};
    const int m_red = tw_tileset_add_material(ts, red), m_glass = tw_tileset_add_material(ts, glass),
              m_yellow = tw_tileset_add_material(ts, yellow),
              m_grey = tw_tileset_add_material(ts, grey);
    int err = tw_tileset_add_prototype(ts, "car", 1.0f) != CAR ||
              tw_tileset_add_prototype(ts, "balloon", 1.0f) != BALLOON ||
              tw_tileset_add_prototype(ts, "wall", 1.0f) != WALL;
    err = err || add_box(ts, CAR, (uint32_t)m_red, 1.8f, 0.9f, 4.4f, 0.3f) ||
          add_box(ts, CAR, (uint32_t)m_glass, 1.6f, 0.7f, 2.2f, 1.2f) ||
          add_box(ts, BALLOON, (uint32_t)m_yellow, 6.0f, 6.0f, 6.0f, 0.0f) ||
          add_box(ts, WALL, (uint32_t)m_grey, 40.0f, 40.0f, 1.0f, 0.0f) ||
          tw_tileset_finish(ts, 0) != TW_OK;
    if (err) {
        tw_tileset_destroy(ts);
        return NULL;
    }
    return ts;
}

/* Car k at frame f: on the streets along the borders of an 8 x 8 block of
 * cells (the city's streets run along every border, 7 m of each side), one
 * car per lane of a cell: two lanes along z at x = 2 and 5, two along x at
 * z = 75 and 78, driving 0.6 m a frame and kept out of the crossings
 * (between 10 and 70 m along), so that no two cars ever touch. */
static struct tw_object car_at(struct tw_cell centre, uint32_t k, uint32_t f)
{
    struct tw_object o = {.model = CAR};
    const uint32_t cell = k / 4, lane = k % 4;
    o.pos.cell.i = centre.i - 4 + (int64_t)(cell % 8);
    o.pos.cell.j = centre.j - 4 + (int64_t)(cell / 8 % 8);
    const float along = 10.0f + fmodf((float)(k * 37 % 60) + 0.6f * (float)f, 60.0f);
    if (lane < 2) {
        o.pos.local[0] = lane ? 5.0f : 2.0f;
        o.pos.local[2] = lane ? along : 80.0f - along;
        o.yaw = lane ? 0.0f : 180.0f;
    } else {
        o.pos.local[0] = lane == 3 ? along : 80.0f - along;
        o.pos.local[2] = lane == 3 ? 75.0f : 78.0f;
        o.yaw = lane == 3 ? 90.0f : 270.0f;
    }
    return o;
}

/* Balloon k at frame f: 100-120 m up (above the city's tallest roofs, 90 m). */
static struct tw_object balloon_at(struct tw_cell centre, uint32_t k, uint32_t f)
{
    struct tw_object o = {.model = BALLOON};
    o.pos.cell.i = centre.i - 3 + (int64_t)(k % 7);
    o.pos.cell.j = centre.j - 3 + (int64_t)(k / 7 % 7);
    o.pos.local[0] = 40.0f + 10.0f * sinf(0.1f * (float)(f + k));
    o.pos.local[1] = 100.0f + (float)(k % 5) * 5.0f;
    o.pos.local[2] = 40.0f;
    return o;
}

/* The wall, 6 m ahead of camera c, across its view. */
static struct tw_object wall_at(const struct tw_camera *c)
{
    struct tw_object o = {.model = WALL, .pos = c->pos, .yaw = c->yaw};
    const float a = c->yaw * 3.14159265f / 180.0f;
    o.pos.local[0] += 6.0f * sinf(a);
    o.pos.local[2] += 6.0f * cosf(a);
    o.pos.local[1] = 0.0f;
    return o;
}

/* A world of s drawn by method m, with the oracle's check every frame. */
static struct tw_world *verified_world(struct tw_world_settings s, enum tw_method m)
{
    s.method = m;
    s.verify = true;
    struct tw_world *w = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    return w;
}

struct run {
    uint64_t missed, triangles_wall;
    uint32_t objects_seen;
    uint32_t image_hash[FRAMES];
};

static uint32_t hash(const uint8_t *p, size_t n)
{
    uint32_t h = 2166136261u;
    for (size_t k = 0; k < n; k++)
        h = (h ^ p[k]) * 16777619u;
    return h;
}

/* FRAMES frames of the street path with method m, objects or none, the wall
 * in front of the camera from frame 6 to 11 (wall true). */
static void walk(struct tw_world_settings s, const struct tw_path *path, enum tw_method m,
                 bool objects, bool wall, struct run *r)
{
    memset(r, 0, sizeof(*r));
    struct tw_world *w = verified_world(s, m);
    if (!w)
        return;
    const struct tw_cell centre = path->keys[0].pos.cell;
    uint32_t ids[CARS + BALLOONS], wall_id = UINT32_MAX;
    for (uint32_t k = 0; objects && k < CARS + BALLOONS; k++) {
        const struct tw_object o = k < CARS ? car_at(centre, k, 0) : balloon_at(centre, k - CARS, 0);
        CHECK(tw_world_object_add(w, &o, &ids[k]) == TW_OK);
    }
    static uint8_t img[W * H * 3];
    for (uint32_t f = 0; f < FRAMES; f++) {
        const struct tw_camera *c = &path->keys[f];
        for (uint32_t k = 0; objects && k < CARS + BALLOONS; k++) {
            const struct tw_object o =
                k < CARS ? car_at(centre, k, f) : balloon_at(centre, k - CARS, f);
            CHECK(tw_world_object_update(w, ids[k], &o) == TW_OK);
        }
        if (wall && f >= 6 && f < 12) {
            const struct tw_object o = wall_at(c);
            if (wall_id == UINT32_MAX)
                CHECK(tw_world_object_add(w, &o, &wall_id) == TW_OK);
            else
                CHECK(tw_world_object_update(w, wall_id, &o) == TW_OK);
        } else if (wall_id != UINT32_MAX) {
            CHECK(tw_world_object_remove(w, wall_id) == TW_OK);
            CHECK(tw_world_object_remove(w, wall_id) == TW_ERR_INVALID);
            wall_id = UINT32_MAX;
        }
        struct tw_frame_stats st;
        CHECK(tw_world_frame(w, c, &st) == TW_OK);
        CHECK_MSG(st.missed_pixels == 0, "%s, frame %u: %llu missed pixels (%u clusters)",
                  tw_method_name(m), f, (unsigned long long)st.missed_pixels,
                  st.missed_clusters);
        r->missed += st.missed_pixels;
        if (f >= 8 && f < 12)
            r->triangles_wall += st.triangles;
        r->objects_seen = st.objects;
        CHECK(tw_world_read_rgb(w, img) == TW_OK);
        r->image_hash[f] = hash(img, sizeof(img));
    }
    tw_world_destroy(w);
}

/* A camera that stands still over cars that move within their cells: the
 * cells' culling state is kept (refits). Then cars moving apart in one cell
 * wear its BVH down until it is built afresh. */
static void refits(struct tw_world_settings s, const struct tw_camera *cam)
{
    struct tw_world *w = verified_world(s, TW_METHOD_TILEQUERY_CHC);
    if (!w)
        return;
    const struct tw_cell centre = cam->pos.cell;
    uint32_t ids[CARS];
    for (uint32_t k = 0; k < CARS; k++) {
        const struct tw_object o = car_at(centre, k, 0);
        CHECK(tw_world_object_add(w, &o, &ids[k]) == TW_OK);
    }
    uint32_t new_tiles = 0, rebuilt = 0, cells = 0;
    for (uint32_t f = 0; f < 12; f++) {
        /* 0.5 m forth and back: never out of the cell. */
        for (uint32_t k = 0; k < CARS; k++) {
            struct tw_object o = car_at(centre, k, 0);
            o.pos.local[k % 4 < 2 ? 2 : 0] += (f & 1) ? 0.5f : 0.0f;
            CHECK(tw_world_object_update(w, ids[k], &o) == TW_OK);
        }
        struct tw_frame_stats st;
        CHECK(tw_world_frame(w, cam, &st) == TW_OK);
        CHECK(st.missed_pixels == 0);
        if (f >= 2) {
            new_tiles += st.tiles_new;
            rebuilt += st.object_rebuilds;
        }
        cells = st.object_cells;
    }
    /* A refit that lost a cell's state would make its tile afresh in every
     * frame, over 60 cells; a cell whose tile query first passes at a later
     * frame makes one tile, once. That happens to one cell here, at the
     * third frame, since the levels of detail were measured both ways (at
     * --max-screen-error 0 and under deterministic queries too; the number
     * of levels moves the contents' numbers; not traced further). */
    CHECK_MSG(cells > 20 && new_tiles <= 2 && rebuilt == 0,
              "standing still over %u cells of moving cars: %u tile instances made afresh, %u "
              "BVHs built afresh (a refit keeps both)", cells, new_tiles, rebuilt);

    /* Cars changing cells: every 4th one into the next cell along j and
     * back, by turns, between cells that always hold cars (not into a cell
     * with none: a cell whose first object comes, or whose last goes,
     * changes what it is). Their cells' BVHs are built afresh, but
     * each cell keeps its composite's key (the group's BVH goes into the
     * slots kept for it), so no tile instance is made afresh: the tile's
     * culling state stays. */
    uint32_t crossed_new = 0, crossed_rebuilt = 0;
    for (uint32_t f = 0; f < 8; f++) {
        for (uint32_t k = 0; k < CARS; k += 4) {
            if (k / 4 / 8 % 8 == 7 || (k / 4 + 8) * 4 >= CARS)
                continue;   /* the next cell along j holds no car */
            struct tw_object o = car_at(centre, k, 0);
            o.pos.cell.j += (int64_t)((f + k / 4) % 2);
            CHECK(tw_world_object_update(w, ids[k], &o) == TW_OK);
        }
        struct tw_frame_stats st;
        CHECK(tw_world_frame(w, cam, &st) == TW_OK);
        CHECK(st.missed_pixels == 0);
        if (f >= 1) {
            crossed_new += st.tiles_new;
            crossed_rebuilt += st.object_rebuilds;
        }
    }
    CHECK_MSG(crossed_rebuilt > 50 && crossed_new == 0,
              "cars changing cells: %u BVHs built afresh, %u tile instances made afresh (the "
              "composites keep their keys)", crossed_rebuilt, crossed_new);

    /* Eight cars of one cell driving apart: the refitted BVH wears down. */
    const struct tw_cell lone = {centre.i + 40, centre.j + 40};
    uint32_t lone_ids[8];
    for (uint32_t k = 0; k < 8; k++) {
        const struct tw_object o = {.pos = {lone, {40.0f, 0.0f, 40.0f + 0.01f * (float)k}},
                                    .model = CAR};
        CHECK(tw_world_object_add(w, &o, &lone_ids[k]) == TW_OK);
    }
    uint32_t rebuilds_apart = 0;
    for (uint32_t f = 0; f < 8; f++) {
        for (uint32_t k = 0; k < 8; k++) {
            const float a = 0.785398f * (float)k, d = 4.0f * (float)(f + 1);
            const struct tw_object o = {
                .pos = {lone, {40.0f + d * cosf(a), 0.0f, 40.0f + d * sinf(a)}}, .model = CAR};
            CHECK(tw_world_object_update(w, lone_ids[k], &o) == TW_OK);
        }
        struct tw_frame_stats st;
        CHECK(tw_world_frame(w, cam, &st) == TW_OK);
        if (f > 0)
            rebuilds_apart += st.object_rebuilds;
    }
    CHECK_MSG(rebuilds_apart >= 1 && rebuilds_apart < 7,
              "cars driving apart in one cell: its BVH built afresh %u times in 7 frames "
              "(refitted in the others)", rebuilds_apart);
    printf("objects: standing still, %u cells of cars refitted for 10 frames: %u tile instances "
           "and %u BVHs made afresh; cars changing cells rebuilt %u BVHs in 7 frames and made %u "
           "tile instances afresh; 8 cars driving apart rebuilt their BVH %u times in 7 frames\n",
           cells, new_tiles, rebuilt, crossed_rebuilt, crossed_new, rebuilds_apart);
    tw_world_destroy(w);
}

/* Balloons high above cells that the street's buildings hide, seen from
 * the street looking up: the cells' tile queries pass only because the
 * common box grew to hold the balloons (a box of the tiles alone is hidden
 * behind the street's buildings, and the propagation would stop there). */
static void sky(struct tw_world_settings s, const struct tw_camera *start)
{
    struct tw_world *w = verified_world(s, TW_METHOD_TILEQUERY_CHC);
    if (!w)
        return;
    const struct tw_cell centre = start->pos.cell;
    uint32_t id;
    for (int64_t di = -4; di <= 4; di++)
        for (int64_t dj = -4; dj <= 4; dj++) {
            const struct tw_object o = {
                .pos = {{centre.i + di, centre.j + dj},
                        {40.0f, 130.0f + 10.0f * (float)((di * 3 + dj + 16) % 9), 40.0f}},
                .model = BALLOON};
            CHECK(tw_world_object_add(w, &o, &id) == TW_OK);
        }
    uint64_t missed = 0, tiles = 0;
    for (uint32_t k = 0; k < 16; k++) {
        struct tw_camera c = *start;
        c.yaw = 22.5f * (float)k;
        c.pitch = 35.0f;
        struct tw_frame_stats st;
        CHECK(tw_world_frame(w, &c, &st) == TW_OK);
        missed += st.missed_pixels;
        tiles += st.tiles_visible;
    }
    CHECK_MSG(missed == 0, "looking up at balloons: %llu missed pixels",
              (unsigned long long)missed);
    printf("objects: balloons 130-210 m up seen from the street in 16 directions, %llu tiles "
           "drawn, %llu missed pixels\n", (unsigned long long)tiles, (unsigned long long)missed);
    tw_world_destroy(w);
}

static void misuse(struct tw_world_settings s, const struct tw_tileset *models)
{
    struct tw_world *w = NULL;
    uint32_t id;
    const struct tw_object car = {.pos = {{0, 0}, {3.0f, 0.0f, 10.0f}}, .model = CAR};
    /* No models: no objects. */
    s.object_models = NULL;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    if (w) {
        CHECK(tw_world_object_add(w, &car, &id) == TW_ERR_STATE);
        CHECK(tw_world_object_remove(w, 0) == TW_ERR_STATE);
        tw_world_destroy(w);
    }
    s.object_models = models;
    CHECK(tw_world_create(&s, &w) == TW_OK);
    if (!w)
        return;
    CHECK(tw_world_object_add(NULL, &car, &id) == TW_ERR_INVALID);
    CHECK(tw_world_object_add(w, NULL, &id) == TW_ERR_INVALID);
    CHECK(tw_world_object_add(w, &car, NULL) == TW_ERR_INVALID);
    struct tw_object bad = car;
    bad.model = 3;
    CHECK(tw_world_object_add(w, &bad, &id) == TW_ERR_INVALID);
    bad = car;
    bad.pos.local[0] = NAN;
    CHECK(tw_world_object_add(w, &bad, &id) == TW_ERR_INVALID);
    bad = car;
    bad.yaw = INFINITY;
    CHECK(tw_world_object_add(w, &bad, &id) == TW_ERR_INVALID);
    CHECK(tw_world_object_update(w, 0, &car) == TW_ERR_INVALID);
    CHECK(tw_world_object_remove(w, 7) == TW_ERR_INVALID);
    /* A position far outside its cell is normalised into the right one. */
    bad = car;
    bad.pos.local[0] = 80.0f * 5 + 3.0f;
    CHECK(tw_world_object_add(w, &bad, &id) == TW_OK);
    CHECK(tw_world_object_remove(w, id) == TW_OK);
    tw_world_destroy(w);
    /* A model that reaches past its cell's neighbours. */
    struct tw_tileset *big = NULL;
    CHECK(tw_tileset_create("big", 80, 80, &big) == TW_OK);
    if (big) {
        const int p = tw_tileset_add_prototype(big, "tower crane", 1.0f);
        const int mat = tw_tileset_add_material(big, (const float[4]){1, 1, 1, 1});
        CHECK(p == 0 && mat == 0 && add_box(big, 0, 0, 120.0f, 2.0f, 2.0f, 0.0f) == TW_OK);
        CHECK(tw_tileset_finish(big, 0) == TW_OK);
        s.object_models = big;
        CHECK(tw_world_create(&s, &w) == TW_ERR_LIMIT);
        tw_tileset_destroy(big);
    }
}

int main(void)
{
    const struct tw_log log = {log_quiet, NULL};
    struct tw_context *ctx = NULL;
    struct tw_tileset *city = NULL, *models = make_models();
    if (!models || tw_context_create_headless(W, H, &log, &ctx) != TW_OK ||
        tw_tilesets_builtin("city", 1, 0, &log, &city) != TW_OK) {
        fprintf(stderr, "test-objects: cannot set up\n");
        return 1;
    }
    struct tw_world_settings s = {0};
    s.tileset = city;
    s.object_models = models;
    s.width = W;
    s.height = H;
    s.view_distance = 320.0f;
    s.deterministic = true;
    s.get_proc = tw_context_get_proc(ctx);
    s.log = log;
    struct tw_path path;
    if (tw_path_builtin("street", 5, FRAMES, 3.0f, 80.0f, 80.0f, &path) != TW_OK)
        return 1;

    static const enum tw_method methods[] = {
        TW_METHOD_VFC, TW_METHOD_TILEQUERY, TW_METHOD_CHC, TW_METHOD_TILEQUERY_CHC,
        TW_METHOD_HZB, TW_METHOD_TILEQUERY_HZB,
    };
    struct run base, r, walled = {0}, bare, open;
    walk(s, &path, TW_METHOD_VFC, true, true, &base);
    CHECK(base.objects_seen == CARS + BALLOONS);
    uint64_t missed = base.missed;
    /* Every method, compared with the oracle frame by frame (walk()):
     * images are not compared with vfc's, as the city's coplanar faces
     * tie in depth and the order of draws picks one (with or without
     * objects). */
    for (size_t k = 1; k < sizeof(methods) / sizeof(methods[0]); k++) {
        walk(s, &path, methods[k], true, true, &r);
        missed += r.missed;
        if (methods[k] == TW_METHOD_TILEQUERY_CHC)
            walled = r;     /* the wall's figures, below */
    }
    /* Objects are drawn: the same method without them (and without the
     * wall, as open) gives other images. */
    walk(s, &path, TW_METHOD_TILEQUERY_CHC, true, false, &open);
    walk(s, &path, TW_METHOD_TILEQUERY_CHC, false, false, &bare);
    uint32_t same = 0;
    for (uint32_t f = 0; f < FRAMES; f++)
        same += bare.image_hash[f] == open.image_hash[f];
    CHECK_MSG(same == 0, "%u of %u images are the same without objects", same, FRAMES);
    /* They occlude: the wall in front of the camera hides the street. */
    CHECK_MSG(walled.triangles_wall * 5 < open.triangles_wall,
              "tilequery+chc, 4 frames behind a wall: %llu triangles, %llu without it",
              (unsigned long long)walled.triangles_wall, (unsigned long long)open.triangles_wall);
    printf("objects: %u cars and balloons, 6 methods, %u frames each, %llu missed pixels; behind "
           "a wall tilequery+chc drew %llu triangles in 4 frames, %llu without it (%.3f)\n",
           CARS + BALLOONS, FRAMES, (unsigned long long)missed,
           (unsigned long long)walled.triangles_wall, (unsigned long long)open.triangles_wall,
           open.triangles_wall ? (double)walled.triangles_wall / (double)open.triangles_wall
                               : 0.0);

    sky(s, &path.keys[0]);
    refits(s, &path.keys[0]);
    misuse(s, models);

    tw_path_finish(&path);
    tw_tileset_destroy(city);
    tw_tileset_destroy(models);
    tw_context_destroy(ctx);
    return check_summary("test-objects");
}
