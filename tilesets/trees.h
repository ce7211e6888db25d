/*
 * Private to tilesets/: the forest's models (trees.c), the meshes that the
 * stand generator (forest-layout.c) places: a few tree species x sizes
 * (conifers of stacked frusta, broadleaves of lumpy blobs, birches), rock
 * shapes, a fallen log and undergrowth patches of bushes or ferns. Each
 * tree model carries a profile (per triangle: lowest point, horizontal
 * reach from the axis) against which a placement is tested exactly. Not
 * installed, not public API.
 */
#ifndef TW_TILESETS_TREES_H
#define TW_TILESETS_TREES_H

#include <stdint.h>

#include "tilesets/mesh-builder.h"
#include "tileworld/tiles.h"

enum {
    TW_TREE_MODELS = 11,    /* tw_tree_recipes */
    TW_ROCK_SHAPES = 4,     /* the last one is the outcrop's */
    TW_PATCH_LEVELS = 3,    /* undergrowth: sparse, medium, dense */
};

/* One size of one species, in metres: the meshes are built at this size
 * and each instance scales it by about 0.85 to 1.15. */
struct tw_tree_recipe {
    uint32_t species;   /* enum tw_forest_species (tilesets-private.h) */
    float height;
    float radius;       /* of the crown */
    float crown_base;   /* lowest point of the crown */
    float trunk_radius;
    uint32_t layers;    /* conifers: frusta; others: blobs */
    uint32_t sides;     /* conifers: sides of each frustum; others: blob subdivision */
};

/* Every species' sizes, smallest first, species by species. */
extern const struct tw_tree_recipe tw_tree_recipes[TW_TREE_MODELS];

/* The models of species: count of them from first, sizes in order. */
void tw_tree_species_models(uint32_t species, uint32_t *first, uint32_t *count);

/* Per triangle of a tree model: its lowest point and its horizontal reach
 * from the axis. */
struct tw_tree_profile {
    float min_y;
    float reach;
};

#define TW_TREE_NO_TRUNK UINT32_MAX

struct tw_tree_model {
    uint32_t canopy, trunk;         /* meshes; trunk: TW_TREE_NO_TRUNK when the canopy hides it */
    float reach;                    /* horizontal reach of any vertex from the axis */
    struct tw_tree_profile *profile;    /* of canopy and trunk together */
    uint32_t profile_count;
};

/* The reach of the triangles of m that come below height (mesh-local y
 * scaled by sy), scaled by sxz; 0 if none does. */
float tw_tree_reach_below(const struct tw_tree_model *m, float height, float sxz, float sy);

/* Undergrowth patches cover a square of side patch_size centred on the
 * origin and keep this far from its edges, so that quarter turns and the
 * walking band leave them whole. */
#define TW_PATCH_MARGIN 1.0f

/* The forest's meshes in one tileset, as mesh indices. Rocks are unit
 * size, lying on y = 0; the log lies along x, centred on the origin. */
struct tw_forest_models {
    struct tw_tree_model trees[TW_TREE_MODELS];     /* as tw_tree_recipes */
    uint32_t rock[TW_ROCK_SHAPES];
    float rock_reach[TW_ROCK_SHAPES];   /* horizontal reach from the axis */
    uint32_t log;
    float log_length, log_radius;
    uint32_t bush_patch[TW_PATCH_LEVELS], fern_patch[TW_PATCH_LEVELS];
    float patch_size;
};

/* Fills m (zeroed by the caller) with meshes drawn from seed, added to ts
 * (unfinished) through the builder b. On failure m may hold profiles:
 * tw_forest_models_finish() frees them either way. */
int tw_forest_models_build(struct tw_forest_models *m, struct tw_mesh_builder *b,
                           struct tw_tileset *ts, uint64_t seed);

/* Copies from into m, with profiles of its own (the same mesh indices). */
int tw_forest_models_copy(struct tw_forest_models *m, const struct tw_forest_models *from);

/* Frees the profiles; the meshes stay in their tileset. */
void tw_forest_models_finish(struct tw_forest_models *m);

#endif
