/*
 * Private to tilesets/: the city's buildings (buildings.c). A building is
 * generated from a small parameter record (struct tw_building_spec) by a
 * pure function; equal records share one set of meshes, so rows of
 * identical houses, matching corner towers and repeated types across
 * prototypes are instanced rather than duplicated. Each building is three
 * meshes (walls, glass, roof) because a material belongs to an instance.
 * Not installed, not public API.
 */
#ifndef TW_TILESETS_BUILDINGS_H
#define TW_TILESETS_BUILDINGS_H

#include <math.h>
#include <stdbool.h>
#include <stdint.h>

#include "tilesets/mesh-builder.h"
#include "tileworld/tiles.h"

/* x rounded to a multiple of step. The city's dimensions are snapped to a
 * grid so that independently drawn buildings coincide now and then and can
 * share meshes. */
static inline float tw_quantize(float x, float step)
{
    return step * floorf(x / step + 0.5f);
}

enum tw_facade_style {
    TW_FACADE_CLASSIC,  /* punched windows with sills, ledges every few floors */
    TW_FACADE_MODERN,   /* punched windows, sparse ledges */
    TW_FACADE_RIBBON,   /* a glass band per floor divided by mullions */
};

/* Everything a building's meshes depend on: equal specs give equal meshes.
 * Mesh-local coordinates: footprint [0, w] x [0, d], ground at y = 0; walls
 * 0 to 3 are those facing -z, +x, +z, -x. */
struct tw_building_spec {
    float w, d;             /* footprint along mesh-local x and z */
    float ground_h, floor_h;
    uint32_t floors;        /* of the base tier, ground floor included */
    uint32_t upper_floors;  /* of the set-back tier; 0: none */
    float inset;            /* set-back on every side */
    float base_bay;         /* window spacing before the triangle budget */
    float bay;              /* window spacing used */
    float window_ratio;     /* window width / bay */
    float recess;
    float parapet_h;
    uint32_t style;         /* enum tw_facade_style */
    uint32_t ledge_every;   /* 0: no intermediate ledges */
    uint32_t blank_mask;    /* base-tier walls without windows (party walls) */
    uint32_t roof;
    uint32_t detail;        /* seeds the rooftop clutter */
    bool balconies;         /* on upper floors of punched facades */
};

/* Draws a building of footprint w x d from r whose top (roof clutter
 * included) stays at or below height: floor heights, window rhythm, roof,
 * and with allow_setback a set-back upper tier on tall wide ones. Walls of
 * blank_mask stay blank if the building is low (tw_building_party_walls()).
 * bay is base_bay. */
void tw_building_spec_init(struct tw_building_spec *sp, struct tw_rng *r, float w, float d,
                           float height, uint32_t style, uint32_t blank_mask,
                           bool allow_setback);

/* The walls of blank_mask that stay blank on a building of height: party
 * walls only on buildings low enough to be hidden by their neighbours (a
 * tower's would show as a huge blank face). */
uint32_t tw_building_party_walls(float height, uint32_t blank_mask);

/* The narrowest window spacing of a facade style. */
float tw_building_min_bay(uint32_t style);

/* The buildings of one tileset: their meshes, made on first use and
 * shared by equal specs. Zero-initialisable; tw_buildings_init(), then
 * tw_buildings_finish(). The tileset is borrowed: it must outlive every
 * call but finish. */
struct tw_cached_building;
struct tw_buildings {
    struct tw_tileset *ts;
    struct tw_cached_building *cache;   /* buildings.c's */
    uint32_t cache_count, cache_cap;
    struct tw_mesh_builder wall, glass, roof;
};

void tw_buildings_init(struct tw_buildings *b, struct tw_tileset *ts);
/* Frees the scratch memory, not the tileset or its meshes. */
void tw_buildings_finish(struct tw_buildings *b);

/* The triangles of the building of sp, counted without being stored. */
uint64_t tw_buildings_triangles(struct tw_buildings *b, const struct tw_building_spec *sp);

/* Adds the building of sp to prototype proto of the tileset under
 * transform (row-major 3x4): one instance per mesh that is not empty,
 * walls, glass and roof in material[0], [1] and [2]. */
int tw_buildings_place(struct tw_buildings *b, uint32_t proto, const struct tw_building_spec *sp,
                       const float transform[12], const uint32_t material[3]);

#endif
