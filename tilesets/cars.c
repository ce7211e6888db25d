/* The car models of the city's traffic (tilesets.h): box cars, a body, a
 * cabin and two axles of wheels, each shape in four colours. */
#include "tilesets/mesh-builder.h"
#include "tilesets/procedural.h"
#include "tilesets/shapes.h"
#include "tilesets/tilesets-private.h"

#include <stdio.h>

/* A box car: a body, a cabin on it and two axles of wheels below it. */
struct car_shape {
    const char *name;
    float length, width;        /* along z, along x */
    float body_lo, body_hi;     /* the body's bottom and top (the wheels fill below) */
    float cabin_back, cabin_front, cabin_top, cabin_inset;
    float axle;                 /* the axles at +-axle along z */
    float colours[4][3];        /* the body's, linear */
};

static const struct car_shape car_shapes[] = {
    {"saloon", 4.5f, 1.8f, 0.3f, 0.95f, -1.25f, 0.85f, 1.45f, 0.1f, 1.4f,
     {{0.60f, 0.05f, 0.04f}, {0.05f, 0.12f, 0.45f}, {0.45f, 0.46f, 0.48f}, {0.03f, 0.03f, 0.035f}}},
    {"hatchback", 4.0f, 1.75f, 0.3f, 0.95f, -1.9f, 0.65f, 1.5f, 0.1f, 1.25f,
     {{0.80f, 0.80f, 0.78f}, {0.80f, 0.60f, 0.05f}, {0.08f, 0.30f, 0.12f}, {0.50f, 0.10f, 0.25f}}},
    {"van", TW_TRAFFIC_CAR_LENGTH, TW_TRAFFIC_CAR_WIDTH, 0.35f, 1.1f, -2.35f, 1.25f, 1.95f, 0.05f,
     1.6f,
     {{0.85f, 0.85f, 0.85f}, {0.45f, 0.46f, 0.48f}, {0.05f, 0.20f, 0.50f}, {0.85f, 0.35f, 0.05f}}},
};

enum { CAR_SHAPES = sizeof(car_shapes) / sizeof(car_shapes[0]), CAR_COLOURS = 4 };

_Static_assert(CAR_SHAPES * CAR_COLOURS == TW_TRAFFIC_CAR_MODELS,
               "TW_TRAFFIC_CAR_MODELS counts the shapes and their colours");

/* Body, cabin and wheels of shape as three meshes of ts. */
static int add_car_meshes(struct tw_tileset *ts, const struct car_shape *c, uint32_t mesh[3])
{
    struct tw_mesh_builder b = {0};
    const float hl = 0.5f * c->length, hw = 0.5f * c->width;
    int err = TW_OK;
    for (int part = 0; part < 3 && !err; part++) {
        tw_mesh_builder_reset(&b, false);
        if (part == 0) {
            const float lo[3] = {-hw, c->body_lo, -hl}, hi[3] = {hw, c->body_hi, hl};
            tw_shape_box(&b, lo, hi, TW_FACES_NO_BOTTOM);
        } else if (part == 1) {
            const float lo[3] = {-hw + c->cabin_inset, c->body_hi, c->cabin_back};
            const float hi[3] = {hw - c->cabin_inset, c->cabin_top, c->cabin_front};
            tw_shape_box(&b, lo, hi, TW_FACES_NO_BOTTOM);
        } else {
            /* The wheels of an axle as one slab, seen below the body. */
            const float r = 0.5f * c->body_lo + 0.03f;
            for (int side = -1; side <= 1; side += 2) {
                const float z = (float)side * c->axle;
                const float lo[3] = {-hw + 0.05f, 0.0f, z - r}, hi[3] = {hw - 0.05f, c->body_lo, z + r};
                tw_shape_box(&b, lo, hi, TW_FACES_SIDES);
            }
        }
        err = tw_mesh_builder_add_to(&b, ts, &mesh[part]);
    }
    tw_mesh_builder_release(&b);
    return err;
}

int tw_tilesets_car_models(const struct tw_log *log, struct tw_tileset **out)
{
    if (!tw_procedural_out_given(out, log, "car models"))
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_tileset *ts = NULL;
    int err = tw_tileset_create("cars", 8.0f, 8.0f, &ts);
    static const float glass[4] = {0.06f, 0.08f, 0.10f, 1.0f};
    static const float tyres[4] = {0.02f, 0.02f, 0.02f, 1.0f};
    int glass_material = err ? err : tw_tileset_add_material(ts, glass);
    int tyre_material = glass_material < 0 ? glass_material : tw_tileset_add_material(ts, tyres);
    if (!err && tyre_material < 0)
        err = tyre_material;
    for (uint32_t s = 0; s < CAR_SHAPES && !err; s++) {
        const struct car_shape *c = &car_shapes[s];
        uint32_t mesh[3];
        if ((err = add_car_meshes(ts, c, mesh)))
            break;
        for (uint32_t k = 0; k < CAR_COLOURS && !err; k++) {
            const float rgba[4] = {c->colours[k][0], c->colours[k][1], c->colours[k][2], 1.0f};
            const int body_material = tw_tileset_add_material(ts, rgba);
            char name[48];
            snprintf(name, sizeof(name), "car-%s-%u", c->name, k);
            const int proto = body_material < 0 ? body_material
                                                : tw_tileset_add_prototype(ts, name, 1.0f);
            if (proto < 0) {
                err = proto;
                break;
            }
            const uint32_t materials[3] = {(uint32_t)body_material, (uint32_t)glass_material,
                                           (uint32_t)tyre_material};
            for (int part = 0; part < 3 && !err; part++) {
                const int inst = tw_tileset_add_instance(ts, (uint32_t)proto, mesh[part],
                                                         materials[part], NULL);
                err = inst < 0 ? inst : TW_OK;
            }
        }
    }
    return tw_procedural_hand_over(ts, err, 2048, log, "car models", out);
}
