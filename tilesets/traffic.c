/* Traffic for the city (tilesets.h): cars driving in the lanes of the
 * streets along every tile border (their models: cars.c).
 *
 * A car's place is a pure function of the traffic, the car and the time:
 * no state is stepped, so a host may ask for any car at any time, on any
 * thread, and get the same bits. Everything is computed in double along a
 * lane of at most 2 * 2273 cells and only the offset inside the cell is
 * rounded to float. */
#include "tiles/tiles-internal.h"
#include "tilesets/procedural.h"
#include "tilesets/tilesets-private.h"

#include <math.h>

void tw_traffic_default_settings(struct tw_traffic_settings *s)
{
    if (!s)
        return;
    *s = (struct tw_traffic_settings){
        .models = TW_TRAFFIC_CAR_MODELS,
        .footprint = 80.0f,
        .street_width = 14.0f,
        .radius_m = 600.0f,
        .speed_mps = 10.0f,
    };
}

/* A centre within this of cell 0 leaves room in int64 for the square
 * around it (a radius of at most 100 km: 2273 cells of 44 m). */
#define CENTRE_LIMIT (INT64_C(1) << 62)     /* inclusive: the command's --start-cell too */

/* A stride through lines street lines coprime with their count: the q-th
 * line taken is q * stride mod lines, every line once, spread over the
 * square, so that a few cars do not all drive near one edge. */
static uint32_t line_stride(uint32_t lines)
{
    for (uint32_t stride = (uint32_t)(0.618 * lines) | 1u;; stride += 2) {
        uint32_t a = stride, b = lines;
        while (b) {
            const uint32_t r = a % b;
            a = b;
            b = r;
        }
        if (a == 1)
            return stride;
    }
}

int tw_traffic_init(struct tw_traffic *t, const struct tw_traffic_settings *settings,
                    const struct tw_log *log)
{
    if (!tw_procedural_out_given(t, log, "traffic"))
        return TW_ERR_INVALID;
    struct tw_traffic_settings s;
    tw_traffic_default_settings(&s);
    if (settings) {
        s.seed = settings->seed;
        s.cars = settings->cars;
        s.centre = settings->centre;
        if (settings->models)
            s.models = settings->models;
        if (settings->footprint != 0.0f)
            s.footprint = settings->footprint;
        if (settings->street_width != 0.0f)
            s.street_width = settings->street_width;
        if (settings->radius_m != 0.0f)
            s.radius_m = settings->radius_m;
        if (settings->speed_mps != 0.0f)
            s.speed_mps = settings->speed_mps;
    }
    /* The streets are the city's: its own checks of its footprint and
     * street width. */
    const struct tw_city_settings requested = {.footprint = s.footprint,
                                               .street_width = s.street_width};
    struct tw_city_settings city;
    int err = tw_city_settings_resolve(&requested, &city, log, "traffic");
    if (err)
        return err;
    if (s.cars > TW_TRAFFIC_MAX_CARS) {
        tw_log_printf(log, TW_LOG_ERROR, "tilesets: traffic: cars = %u, at most %u (caller's "
                      "settings)", s.cars, TW_TRAFFIC_MAX_CARS);
        return TW_ERR_INVALID;
    }
    if (!tw_procedural_in_range(s.radius_m, 1.0f, 100000.0f, "radius_m", " m", log, "traffic") ||
        !tw_procedural_in_range(s.speed_mps, 0.0f, 100.0f, "speed_mps", " m/s", log, "traffic"))
        return TW_ERR_INVALID;
    if (s.centre.i < -CENTRE_LIMIT || s.centre.i > CENTRE_LIMIT ||
        s.centre.j < -CENTRE_LIMIT || s.centre.j > CENTRE_LIMIT) {
        tw_log_printf(log, TW_LOG_ERROR, "tilesets: traffic: centre = (%lld, %lld), each within "
                      "+-2^62 (caller's settings)", (long long)s.centre.i, (long long)s.centre.j);
        return TW_ERR_INVALID;
    }
    t->settings = s;
    t->half_cells = (int64_t)ceil((double)s.radius_m / (double)s.footprint);
    if (t->half_cells < 1)
        t->half_cells = 1;
    t->lanes = (uint32_t)(8 * t->half_cells);
    t->lane_length = 2.0 * (double)t->half_cells * (double)s.footprint;
    t->road_half_width = tw_city_road_half_width(&city);
    t->lane_offset = 0.5f * t->road_half_width;
    t->line_stride = line_stride((uint32_t)(2 * t->half_cells));
    return TW_OK;
}

/* Uniform in [0, 1) from 53 bits of a hash. */
static double unit(uint64_t h)
{
    return (double)(h >> 11) * (1.0 / 9007199254740992.0);
}

int tw_traffic_place(const struct tw_traffic *t, uint32_t car, double seconds,
                     struct tw_traffic_car *out)
{
    if (!t || !out || car >= t->settings.cars || !isfinite(seconds))
        return TW_ERR_INVALID;
    const struct tw_traffic_settings *s = &t->settings;
    /* Lane l: bit 0 the axis (0: along x), bit 1 the way (0: towards +),
     * the rest the street line, so that consecutive cars spread over axes,
     * ways and lines alike. */
    const uint32_t lane = car % t->lanes, slot = car / t->lanes;
    const uint32_t in_lane = s->cars / t->lanes + (lane < s->cars % t->lanes ? 1u : 0u);
    const bool along_x = (lane & 1u) == 0, forward = (lane & 2u) == 0;
    const uint32_t lines = (uint32_t)(2 * t->half_cells);
    const int64_t line =
        (int64_t)(((uint64_t)(lane >> 2) * t->line_stride) % lines) - t->half_cells;

    const double spacing = t->lane_length / in_lane;
    const double phase = unit(tw_tiles_hash(s->seed, lane, 0x6c616e65)) * spacing;
    const double speed = s->speed_mps * (0.8 + 0.4 * unit(tw_tiles_hash(s->seed, lane, 0x73706565)));
    double u = fmod(phase + slot * spacing + speed * seconds, t->lane_length);
    if (u < 0.0)
        u += t->lane_length;
    if (!forward)
        u = t->lane_length - u;     /* in (0, L]: L is the square's edge, as 0 is */
    const double w = s->footprint;
    const double cells = floor(u / w);

    /* Right-hand traffic: driving along +x the lane lies towards +z of the
     * centre line, along +z towards -x (y up). */
    const float side = forward == along_x ? 1.0f : -1.0f;
    const int64_t along_cell = (along_x ? s->centre.i : s->centre.j) - t->half_cells + (int64_t)cells;
    const int64_t across_cell = (along_x ? s->centre.j : s->centre.i) + line;
    const float along = (float)(u - cells * w), across = side * t->lane_offset;
    struct tw_traffic_car c;
    c.pos.cell.i = along_x ? along_cell : across_cell;
    c.pos.cell.j = along_x ? across_cell : along_cell;
    c.pos.local[0] = along_x ? along : across;
    c.pos.local[1] = 0.0f;
    c.pos.local[2] = along_x ? across : along;
    c.yaw = along_x ? (forward ? 90.0f : 270.0f) : (forward ? 0.0f : 180.0f);
    c.model = (uint32_t)(tw_tiles_hash(s->seed, car, 0x6d6f64656c) % s->models);
    const int err = tw_tiles_normalize(&c.pos, s->footprint, s->footprint);
    if (err)
        return err;
    *out = c;
    return TW_OK;
}
