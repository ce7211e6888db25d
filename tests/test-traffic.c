/* Tests of the city's traffic (tilesets/traffic.c): the car models, and cars
 * that are a pure function of (traffic, car, time), drive on the road in
 * their lane and never in a block (checked against the boxes of everything
 * standing in the city's, the hybrid's and city-gen's tiles), face the way
 * they drive, keep their distance in a lane and wrap inside their square.
 * Plain C: main returns 0 when every check holds. */
#include "tileworld/tilesets.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tests/captured-log.h"
#include "tests/check.h"
#include "tiles/tiles-internal.h"

/* A car's centre relative to the traffic's centre corner, metres (double:
 * exact for the cells a test uses). */
static void world_xz(const struct tw_traffic *t, const struct tw_traffic_car *c, double xz[2])
{
    const double w = t->settings.footprint;
    xz[0] = (double)(c->pos.cell.i - t->settings.centre.i) * w + c->pos.local[0];
    xz[1] = (double)(c->pos.cell.j - t->settings.centre.j) * w + c->pos.local[2];
}

static bool boxes_overlap(const struct tw_box *a, const struct tw_box *b)
{
    for (int k = 0; k < 3; k++)
        if (a->min[k] >= b->max[k] || b->min[k] >= a->max[k])
            return false;
    return true;
}

/* The car's box (the largest model's, turned to its yaw) in its cell's
 * tile-local coordinates, from bottom to 2 m up. */
static struct tw_box car_box(const struct tw_traffic_car *c, float bottom)
{
    const bool along_x = c->yaw == 90.0f || c->yaw == 270.0f;
    const float hx = 0.5f * (along_x ? TW_TRAFFIC_CAR_LENGTH : TW_TRAFFIC_CAR_WIDTH);
    const float hz = 0.5f * (along_x ? TW_TRAFFIC_CAR_WIDTH : TW_TRAFFIC_CAR_LENGTH);
    return (struct tw_box){{c->pos.local[0] - hx, bottom, c->pos.local[2] - hz},
                           {c->pos.local[0] + hx, 2.0f, c->pos.local[2] + hz}};
}

/* The boxes of what stands in a tile: every instance (the merged ones by
 * the instances merged into them) whose top is above the kerb. */
static uint32_t standing_hits(const struct tw_tileset *ts, uint32_t proto,
                              const struct tw_box *car)
{
    const struct tw_prototype *p = &ts->prototypes[proto];
    uint32_t hits = 0;
    for (uint32_t k = 0; k < p->instance_count; k++) {
        const struct tw_instance *in = &p->instances[k];
        if (in->merged || in->box.max[1] <= 0.2f)
            continue;
        hits += boxes_overlap(&in->box, car);
    }
    return hits;
}

/* Hits of car c against prototype proto of ts in every cell its box
 * reaches. */
static uint32_t car_hits(const struct tw_tileset *ts, uint32_t proto,
                         const struct tw_traffic_car *c)
{
    const float w = ts->footprint[0];
    const struct tw_box b = car_box(c, 0.2f);
    uint32_t hits = 0;
    for (int di = -1; di <= 1; di++)
        for (int dj = -1; dj <= 1; dj++) {
            const struct tw_box in_cell = {
                {b.min[0] - di * w, b.min[1], b.min[2] - dj * w},
                {b.max[0] - di * w, b.max[1], b.max[2] - dj * w}};
            const struct tw_box tile = {{0.0f, -1.0f, 0.0f}, {w, 1000.0f, w}};
            if (boxes_overlap(&in_cell, &tile))
                hits += standing_hits(ts, proto, &in_cell);
        }
    return hits;
}

static void test_car_models(void)
{
    struct captured_log cap = {0};
    const struct tw_log log = {capture, &cap};
    struct tw_tileset *a = NULL, *b = NULL;
    CHECK(tw_tilesets_car_models(&log, &a) == TW_OK);
    CHECK(tw_tilesets_car_models(&log, &b) == TW_OK);
    CHECK(tw_tilesets_car_models(&log, NULL) == TW_ERR_INVALID);
    if (!a || !b)
        goto out;
    CHECK(a->finished);
    CHECK_MSG(a->prototype_count == TW_TRAFFIC_CAR_MODELS, "%u", a->prototype_count);
    for (uint32_t p = 0; p < a->prototype_count; p++) {
        const struct tw_prototype *m = &a->prototypes[p];
        CHECK_MSG(m->triangle_count >= 24 && m->triangle_count <= 40, "%s: %llu triangles",
                  m->name, (unsigned long long)m->triangle_count);
        CHECK_MSG(m->cluster_count == 1, "%s: %u clusters", m->name, m->cluster_count);
        /* On the ground at its centre, within the largest car. */
        const struct tw_box *x = &m->box;
        CHECK_MSG(x->min[1] == 0.0f && x->max[1] <= 2.0f, "%s: y %g..%g", m->name,
                  x->min[1], x->max[1]);
        CHECK_MSG(x->max[2] <= 0.5f * TW_TRAFFIC_CAR_LENGTH &&
                  x->min[2] >= -0.5f * TW_TRAFFIC_CAR_LENGTH &&
                  x->max[0] <= 0.5f * TW_TRAFFIC_CAR_WIDTH &&
                  x->min[0] >= -0.5f * TW_TRAFFIC_CAR_WIDTH, "%s", m->name);
        /* Centred across, its length about the centre. */
        CHECK_MSG(x->min[0] == -x->max[0] && x->min[2] == -x->max[2], "%s", m->name);
        /* Deterministic. */
        CHECK(b->prototypes[p].triangle_count == m->triangle_count &&
              memcmp(&b->prototypes[p].box, x, sizeof(*x)) == 0);
    }
out:
    tw_tileset_destroy(a);
    tw_tileset_destroy(b);
    CHECK_MSG(cap.errors == 1, "%u: %s", cap.errors, cap.last);   /* the NULL out */
}

static void test_settings(void)
{
    struct captured_log cap = {0};
    const struct tw_log log = {capture, &cap};
    struct tw_traffic t;
    CHECK(tw_traffic_init(&t, NULL, &log) == TW_OK);
    CHECK(t.settings.footprint == 80.0f && t.settings.street_width == 14.0f);
    CHECK(t.settings.models == TW_TRAFFIC_CAR_MODELS && t.settings.cars == 0);
    /* 600 m: 8 cells each side of the centre, 16 lines each way. */
    CHECK_MSG(t.half_cells == 8 && t.lanes == 64 && t.lane_length == 1280.0, "%lld %u %g",
              (long long)t.half_cells, t.lanes, t.lane_length);
    /* The city's road: 14 m streets, 3.08 m of sidewalk each side. */
    CHECK_MSG(fabsf(t.road_half_width - 3.92f) < 1e-5f, "%g", t.road_half_width);
    struct tw_traffic_car c;
    CHECK(tw_traffic_place(&t, 0, 0.0, &c) == TW_ERR_INVALID);   /* no car */

    const struct {
        struct tw_traffic_settings s;
        const char *said;
    } bad[] = {
        {{.cars = TW_TRAFFIC_MAX_CARS + 1}, "cars"},
        {{.radius_m = 0.5f}, "radius_m"},
        {{.radius_m = NAN}, "radius_m"},
        {{.speed_mps = -1.0f}, "speed_mps"},
        {{.speed_mps = 101.0f}, "speed_mps"},
        {{.street_width = 2.0f}, "street_width"},
        {{.footprint = 30.0f}, "footprint"},
        {{.centre = {INT64_MAX, 0}}, "centre"},
    };
    for (size_t k = 0; k < sizeof(bad) / sizeof(bad[0]); k++) {
        cap.last[0] = '\0';
        CHECK_MSG(tw_traffic_init(&t, &bad[k].s, &log) == TW_ERR_INVALID, "%s", bad[k].said);
        CHECK_MSG(strstr(cap.last, bad[k].said) != NULL, "%s: %s", bad[k].said, cap.last);
    }
    CHECK(tw_traffic_init(NULL, NULL, &log) == TW_ERR_INVALID);
    /* The command's farthest start cell, 2^62, and its cars at the edge of
     * the square there. */
    const struct tw_traffic_settings edge = {.cars = 64, .centre = {INT64_C(1) << 62,
                                                                     -(INT64_C(1) << 62)}};
    CHECK(tw_traffic_init(&t, &edge, &log) == TW_OK);
    for (uint32_t k = 0; k < 64; k++) {
        struct tw_traffic_car e;
        CHECK(tw_traffic_place(&t, k, 1000.0, &e) == TW_OK);
        CHECK(e.pos.cell.i - edge.centre.i >= -9 && e.pos.cell.i - edge.centre.i <= 8);
    }
    const struct tw_traffic_settings beyond = {.centre = {0, -(INT64_C(1) << 62) - 1}};
    CHECK(tw_traffic_init(&t, &beyond, &log) == TW_ERR_INVALID);

    const struct tw_traffic_settings one = {.cars = 1};
    CHECK(tw_traffic_init(&t, &one, &log) == TW_OK);
    CHECK(tw_traffic_place(&t, 0, 0.0, &c) == TW_OK);
    CHECK(tw_traffic_place(&t, 1, 0.0, &c) == TW_ERR_INVALID);
    CHECK(tw_traffic_place(&t, 0, INFINITY, &c) == TW_ERR_INVALID);
    CHECK(tw_traffic_place(&t, 0, NAN, &c) == TW_ERR_INVALID);
    CHECK(tw_traffic_place(&t, 0, 0.0, NULL) == TW_ERR_INVALID);
}

/* A pure function: the same bits whatever was asked before, and at a far
 * centre the same places relative to it. */
static void test_determinism(void)
{
    const struct tw_traffic_settings s = {.seed = 7, .cars = 2000, .centre = {3, -5}};
    struct tw_traffic t, far;
    CHECK(tw_traffic_init(&t, &s, NULL) == TW_OK);
    struct tw_traffic_settings fs = s;
    fs.centre = (struct tw_cell){INT64_C(1) << 40, -(INT64_C(1) << 40)};
    CHECK(tw_traffic_init(&far, &fs, NULL) == TW_OK);
    static const double times[] = {0.0, 1.0 / 30.0, 12.5, 1234.5678, -3.0, 86400.0};
    enum { TIMES = sizeof(times) / sizeof(times[0]) };
    struct tw_traffic_car *first = calloc((size_t)s.cars * TIMES, sizeof(*first));
    if (!first)
        return;
    uint32_t models_seen = 0;
    for (uint32_t k = 0; k < s.cars; k++)
        for (int n = 0; n < TIMES; n++) {
            CHECK(tw_traffic_place(&t, k, times[n], &first[k * TIMES + n]) == TW_OK);
            models_seen |= 1u << first[k * TIMES + n].model;
        }
    CHECK_MSG(models_seen == (1u << TW_TRAFFIC_CAR_MODELS) - 1, "%x", models_seen);
    uint32_t differ = 0, far_differ = 0, moved = 0;
    for (uint32_t k = s.cars; k-- > 0;)
        for (int n = TIMES; n-- > 0;) {
            struct tw_traffic_car c, f;
            tw_traffic_place(&t, k, times[n], &c);
            differ += memcmp(&c, &first[k * TIMES + n], sizeof(c)) != 0;
            tw_traffic_place(&far, k, times[n], &f);
            far_differ += memcmp(f.pos.local, c.pos.local, sizeof(c.pos.local)) != 0 ||
                          f.yaw != c.yaw || f.model != c.model ||
                          f.pos.cell.i - fs.centre.i != c.pos.cell.i - s.centre.i ||
                          f.pos.cell.j - fs.centre.j != c.pos.cell.j - s.centre.j;
            moved += n > 0 && memcmp(&first[k * TIMES + n].pos, &first[k * TIMES].pos,
                                     sizeof(c.pos)) != 0;
        }
    CHECK_MSG(differ == 0, "%u", differ);
    CHECK_MSG(far_differ == 0, "%u", far_differ);
    CHECK_MSG(moved == s.cars * (TIMES - 1), "%u", moved);
    /* Another seed is other traffic. */
    struct tw_traffic_settings s2 = s;
    s2.seed = 8;
    struct tw_traffic t2;
    CHECK(tw_traffic_init(&t2, &s2, NULL) == TW_OK);
    uint32_t same = 0;
    for (uint32_t k = 0; k < s.cars; k++) {
        struct tw_traffic_car c;
        tw_traffic_place(&t2, k, 0.0, &c);
        same += memcmp(&c.pos, &first[k * TIMES].pos, sizeof(c.pos)) == 0;
    }
    CHECK_MSG(same < s.cars / 100, "%u", same);
    free(first);
}

/* A car by lane (its way and line) and place along it. */
struct in_lane {
    float yaw;
    double across, along;
};

static int compare_in_lane(const void *pa, const void *pb)
{
    const struct in_lane *a = pa, *b = pb;
    if (a->yaw != b->yaw)
        return a->yaw < b->yaw ? -1 : 1;
    if (a->across != b->across)
        return a->across < b->across ? -1 : 1;
    return (a->along > b->along) - (a->along < b->along);
}

/* Every car on the road in its lane, facing the way it drives, inside the
 * square, its lane's cars apart; never in what stands in a city tile. */
static void check_traffic(const struct tw_traffic *t, const struct tw_tileset *const *tilesets,
                          uint32_t tileset_count, const char *what)
{
    const struct tw_traffic_settings *s = &t->settings;
    const double w = s->footprint, half = (double)t->half_cells * w;
    const float d = t->lane_offset;
    const float hw = 0.5f * TW_TRAFFIC_CAR_WIDTH;
    uint32_t off_road = 0, wrong_side = 0, outside = 0, wrong_yaw = 0, too_close = 0, hits = 0;
    uint32_t wraps = 0, far_low = 0, far_high = 0;
    double min_gap = 1e300;
    struct tw_traffic_car *cars = calloc(s->cars, sizeof(*cars));
    double (*xz)[2] = calloc(s->cars, sizeof(*xz));
    struct in_lane *order = calloc(s->cars, sizeof(*order));
    if (!cars || !xz || !order)
        goto out;
    for (double time = 0.0; time < 300.0; time += 7.25) {
        for (uint32_t k = 0; k < s->cars; k++) {
            struct tw_traffic_car *c = &cars[k];
            if (tw_traffic_place(t, k, time, c) != TW_OK) {
                CHECK_MSG(false, "%s: car %u at %g s", what, k, time);
                continue;
            }
            world_xz(t, c, xz[k]);
            const bool along_x = c->yaw == 90.0f || c->yaw == 270.0f;
            CHECK(along_x || c->yaw == 0.0f || c->yaw == 180.0f);
            CHECK(c->pos.local[1] == 0.0f);
            CHECK(c->pos.local[0] >= 0.0f && c->pos.local[0] < (float)w &&
                  c->pos.local[2] >= 0.0f && c->pos.local[2] < (float)w);
            /* Across the street: its distance from the border line. */
            const float across = along_x ? c->pos.local[2] : c->pos.local[0];
            const float from_line = fminf(across, (float)w - across);
            off_road += from_line + hw > t->road_half_width;
            wrong_side += from_line - hw < 0.25f || fabsf(from_line - d) > 1e-3f;
            /* Right-hand traffic: the lane lies to the driver's right. */
            const float right = across < 0.5f * (float)w ? 1.0f : -1.0f;   /* + side of the line */
            const bool expect_plus = c->yaw == 90.0f || c->yaw == 180.0f;
            wrong_side += (right > 0.0f) != expect_plus;
            for (int a = 0; a < 2; a++) {
                outside += xz[k][a] < -half - d - 1e-3 || xz[k][a] > half + 1e-3;
                far_low += xz[k][a] < -0.5 * half;
                far_high += xz[k][a] > 0.5 * half;
            }
            for (uint32_t n = 0; n < tileset_count; n++)
                for (uint32_t p = 0; p < tilesets[n]->prototype_count; p++)
                    hits += car_hits(tilesets[n], p, c);
            /* Facing the way it drives: a moment later it has moved along its yaw. */
            struct tw_traffic_car later;
            tw_traffic_place(t, k, time + 0.1, &later);
            double lxz[2];
            world_xz(t, &later, lxz);
            const double dx = lxz[0] - xz[k][0], dz = lxz[1] - xz[k][1];
            const double step = hypot(dx, dz);
            if (step > 10.0) {
                wraps++;
                continue;
            }
            const double yaw = c->yaw * 3.14159265358979323846 / 180.0;
            wrong_yaw += step < 0.07 * s->speed_mps || step > 0.13 * s->speed_mps ||
                         (dx * sin(yaw) + dz * cos(yaw)) < 0.999 * step;
        }
        /* Cars of a lane (same way, same line) keep their distance: sorted
         * by lane and place, each from the next, the last from the first. */
        for (uint32_t k = 0; k < s->cars; k++) {
            const int a = cars[k].yaw == 90.0f || cars[k].yaw == 270.0f ? 0 : 1;
            order[k] = (struct in_lane){cars[k].yaw, xz[k][1 - a], xz[k][a]};
        }
        qsort(order, s->cars, sizeof(*order), compare_in_lane);
        for (uint32_t k = 0, first = 0; k < s->cars; k++) {
            const bool last = k + 1 == s->cars || order[k + 1].yaw != order[k].yaw ||
                              order[k + 1].across != order[k].across;
            const uint32_t next = last ? first : k + 1;
            if (next == k)
                continue;
            double gap = fabs(order[next].along - order[k].along);
            gap = fmin(gap, t->lane_length - gap);
            min_gap = fmin(min_gap, gap);
            too_close += gap < TW_TRAFFIC_CAR_LENGTH + 0.5;
            if (last)
                first = k + 1;
        }
    }
    CHECK_MSG(off_road == 0, "%s: %u off the road", what, off_road);
    CHECK_MSG(wrong_side == 0, "%s: %u not in their lane", what, wrong_side);
    CHECK_MSG(outside == 0, "%s: %u outside the square", what, outside);
    CHECK_MSG(wrong_yaw == 0, "%s: %u not driving along their yaw", what, wrong_yaw);
    CHECK_MSG(too_close == 0, "%s: %u too close in a lane (closest %g m)", what, too_close,
              min_gap);
    CHECK_MSG(hits == 0, "%s: %u boxes of standing things hit", what, hits);
    /* Over 300 s every car drives 240 to 360 m: across the square, wrapping. */
    CHECK_MSG(far_low > 0 && far_high > 0, "%s: %u %u", what, far_low, far_high);
    CHECK_MSG(s->cars < 100 || wraps > 0, "%s: no car wrapped", what);
out:
    free(order);
    free(cars);
    free(xz);
}

static void test_on_the_streets(void)
{
    struct captured_log cap = {0};
    const struct tw_log log = {capture, &cap};
    struct tw_tileset *city = NULL, *hybrid = NULL;
    struct tw_tilesets_provider *p = NULL;
    CHECK(tw_tilesets_builtin("city", 1, 0, &log, &city) == TW_OK);
    CHECK(tw_tilesets_builtin("hybrid", 1, 0, &log, &hybrid) == TW_OK);
    /* city-gen: a few generated cells in one tileset of their own each,
     * gathered as prototypes of one for the check. */
    CHECK(tw_tilesets_provider_create("city-gen", 1, 0, &log, &p) == TW_OK);
    const struct tw_tile_provider *tp = tw_tilesets_provider_get(p);
    struct tw_tileset *cells[6] = {0};
    uint32_t cell_count = 0;
    for (int k = 0; k < 6 && tp; k++) {
        if (tw_tileset_create("cell", tp->footprint[0], tp->footprint[1], &cells[k]) != TW_OK)
            break;
        const int rc = tp->generate(tp->user, (struct tw_cell){k, 2 * k - 3}, cells[k]);
        CHECK(rc == TW_OK);
        if (rc == TW_OK && tw_tileset_finish(cells[k], 2048) == TW_OK)
            cell_count++;
    }
    if (!city || !hybrid || cell_count < 6)
        goto out;
    const struct tw_tileset *sets[] = {city, hybrid, cells[0], cells[1], cells[2], cells[3],
                                       cells[4], cells[5]};
    /* Few cars, each checked against every tile; then traffic as dense
     * as 10 000 cars in 600 m (157 cars a lane, 8.2 m apart), in the
     * lanes only. */
    struct tw_traffic t;
    const struct tw_traffic_settings few = {.seed = 3, .cars = 150, .radius_m = 300.0f};
    CHECK(tw_traffic_init(&t, &few, NULL) == TW_OK);
    check_traffic(&t, sets, sizeof(sets) / sizeof(sets[0]), "150 cars");
    const struct tw_traffic_settings dense = {.seed = 4, .cars = 2500, .radius_m = 300.0f,
                                              .speed_mps = 14.0f, .centre = {-7, 11}};
    CHECK(tw_traffic_init(&t, &dense, NULL) == TW_OK);
    check_traffic(&t, NULL, 0, "2500 cars in 300 m");
    /* Another city: wider streets, larger blocks. */
    const struct tw_traffic_settings wide = {.cars = 200, .footprint = 120.0f,
                                             .street_width = 20.0f, .radius_m = 500.0f};
    CHECK(tw_traffic_init(&t, &wide, NULL) == TW_OK);
    struct tw_city_settings cs = {.footprint = 120.0f, .street_width = 20.0f};
    struct tw_tileset *wide_city = NULL;
    CHECK(tw_tilesets_city(5, &cs, &log, &wide_city) == TW_OK);
    if (wide_city) {
        const struct tw_tileset *one[] = {wide_city};
        check_traffic(&t, one, 1, "200 cars, 120 m blocks");
    }
    tw_tileset_destroy(wide_city);
out:
    for (int k = 0; k < 6; k++)
        tw_tileset_destroy(cells[k]);
    tw_tilesets_provider_destroy(p);
    tw_tileset_destroy(city);
    tw_tileset_destroy(hybrid);
}

int main(void)
{
    test_car_models();
    test_settings();
    test_determinism();
    test_on_the_streets();
    return check_summary("test-traffic");
}
