/*
 * tilesets-private.h: generator internals shared between the tilesets'
 * translation units, and the library-internal functions that the
 * programs (tools/) and the tests call. Not public API, not installed.
 *
 * The hybrid tileset (hybrid.c) is made of the city's blocks (city-layout.c)
 * and the forest's stands (forest-layout.c). Both generators keep their
 * state in an opaque object that adds its materials and shared meshes to a
 * tileset the caller created, and then adds one block or stand to a
 * prototype per call.
 * The tileset stays owned by the caller; the generator objects borrow it:
 * it must outlive every call on them but destroy, which never touches it.
 */
#ifndef TW_TILESETS_PRIVATE_H
#define TW_TILESETS_PRIVATE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "tileworld/tilesets.h"

/* ---- the city's block generator (city.c, city-layout.c) ------------------------- */

/* Validates in (NULL: all defaults) and fills every field of out, defaults
 * resolved. Messages name who ("city", "hybrid") as the generator the
 * caller's settings were for. */
int tw_city_settings_resolve(const struct tw_city_settings *in, struct tw_city_settings *out,
                             const struct tw_log *log, const char *who);

enum tw_city_block_kind {
    TW_CITY_BLOCK_DENSE,    /* perimeter blocks and courtyard towers up to max_height */
    TW_CITY_BLOCK_LOWRISE,  /* two to four floors */
    TW_CITY_BLOCK_PARK,     /* lawns, paths, a fountain, trees; low houses on two sides */
};

struct tw_city_blocks;

/* Adds the city's materials and shared ground meshes to ts (unfinished,
 * footprint settings->footprint square). settings must be resolved by
 * tw_city_settings_resolve(). The caller owns *out. */
int tw_city_blocks_create(struct tw_tileset *ts, const struct tw_city_settings *settings,
                          struct tw_city_blocks **out);
/* The same for a tileset that holds one block (a provider's tile): the
 * meshes that only parks use are made by the first park, not up front, so
 * the tileset holds no mesh that it does not draw. */
int tw_city_blocks_create_tile(struct tw_tileset *ts, const struct tw_city_settings *settings,
                               struct tw_city_blocks **out);
/* Frees the generator's scratch memory, not the tileset; accepts NULL. */
void tw_city_blocks_destroy(struct tw_city_blocks *blocks);

/* The highest tile-local y that any block (every kind, any stream) made with
 * settings (resolved) can reach: a bound from the generator's own limits. */
float tw_city_blocks_max_top(const struct tw_city_settings *settings);

/* Adds a whole block of kind to prototype proto: streets, ground, lots.
 * stream seeds the block's random numbers (e.g. tw_tiles_hash(seed, k,
 * tag)); tallest makes a dense block reach max_height. */
int tw_city_blocks_add(struct tw_city_blocks *blocks, uint32_t proto,
                       enum tw_city_block_kind kind, uint64_t stream, bool tallest);

/* Adds only the streets, sidewalks, lamps and the block's ground, the
 * ground in ground_material (a material of the tileset), for blocks that
 * fill the lot area themselves. */
int tw_city_blocks_add_streets(struct tw_city_blocks *blocks, uint32_t proto,
                               uint32_t ground_material);

/* Where the road ends and the sidewalk (its kerb) begins, metres from the
 * tile border: the road, kerb to kerb, spans that much either side of every
 * border. settings must be resolved. */
float tw_city_road_half_width(const struct tw_city_settings *settings);

/* The lot area that the streets leave, as {x0, z0, x1, z1} in tile-local
 * metres, and the height of its ground (the kerb). */
void tw_city_blocks_lot_area(const struct tw_city_blocks *blocks, float area[4],
                             float *ground_y);

/* ---- the forest's stand generator (forest.c, forest-layout.c) --------------------- */

/* Validates in (NULL: all defaults) and fills every field of out; messages
 * name who. */
int tw_forest_settings_resolve(const struct tw_forest_settings *in,
                               struct tw_forest_settings *out, const struct tw_log *log,
                               const char *who);

enum tw_forest_stand_kind {
    TW_FOREST_STAND_SPRUCE,     /* dense conifers, skirts to the ground */
    TW_FOREST_STAND_MIXED,      /* dense conifers and broadleaves */
    TW_FOREST_STAND_BEECH,      /* tall broadleaves over saplings */
    TW_FOREST_STAND_BIRCH,      /* a birch grove with pines */
    TW_FOREST_STAND_THIN,       /* a thinner stand, more undergrowth */
    TW_FOREST_STAND_CLEARING,   /* a glade in the middle, trees round it */
    TW_FOREST_STAND_ROCKY,      /* boulders and outcrops among pines */
    TW_FOREST_STAND_KIND_COUNT,
};

/* A short name of a stand kind ("spruce", "clearing", ...); never NULL. */
const char *tw_forest_stand_name(enum tw_forest_stand_kind kind);

/* Where a stand goes inside its prototype. */
struct tw_forest_area {
    float rect[4];      /* {x0, z0, x1, z1}: everything stays inside, canopies included */
    float ground_y;     /* height of the ground the stand stands on */
    /* Walking clearance along the tile borders x = 0, x = W, z = 0, z = D:
     * within band metres of one, nothing stands between ground_y + 0.05 m
     * and ground_y + TW_FOREST_HEADROOM (no trunk, no bush, no low branch).
     * 0: no band. */
    float band;
};

/* Height above the ground below which the walking band is clear (m). */
#define TW_FOREST_HEADROOM 2.5f

struct tw_forest_stands;

/* Adds the forest's materials and its shared meshes (tree species x
 * sizes, rocks, logs, undergrowth patches) to ts, drawn from seed.
 * settings must be resolved by tw_forest_settings_resolve(). The caller
 * owns *out. */
int tw_forest_stands_create(struct tw_tileset *ts, uint64_t seed,
                            const struct tw_forest_settings *settings,
                            struct tw_forest_stands **out);
/* Frees the generator's scratch memory, not the tileset; accepts NULL. */
void tw_forest_stands_destroy(struct tw_forest_stands *stands);

/* Adds a stand of kind inside area to prototype proto: trees (one or two
 * instances each: canopy, trunk), rocks, logs and undergrowth patches. The
 * tree count scales with the area and settings->density. stream seeds the
 * stand's random numbers. */
int tw_forest_stands_add(struct tw_forest_stands *stands, uint32_t proto,
                         enum tw_forest_stand_kind kind, uint64_t stream,
                         const struct tw_forest_area *area);

/* The forest floor's material, for the ground under a stand. */
uint32_t tw_forest_stands_floor_material(const struct tw_forest_stands *stands);

/* ---- the forest's stands in generated tiles (forest-gen) ---- */

/* Tree species, in the order of a stand's species mix. */
enum tw_forest_species {
    TW_FOREST_SPECIES_SPRUCE,
    TW_FOREST_SPECIES_FIR,
    TW_FOREST_SPECIES_PINE,
    TW_FOREST_SPECIES_BEECH,
    TW_FOREST_SPECIES_BIRCH,
    TW_FOREST_SPECIES_COUNT,
};

/* A generator on ts (unfinished, model's footprint) that places model's
 * trees, rocks and patches without drawing them again: each mesh is copied
 * into ts when it is first placed there (ts holds no mesh it does not
 * draw); the materials are copied at once. model (made by
 * tw_forest_stands_create()) and its tileset are only read, by any number
 * of threads at once, and must not change while the generator lives. The
 * caller owns *out. */
int tw_forest_stands_create_from(const struct tw_forest_stands *model, struct tw_tileset *ts,
                                 struct tw_forest_stands **out);

/* Adds the forest floor over the whole tile and the trail along every
 * border (band metres wide, a hair above the floor) to prototype proto, as
 * the forest tileset has them; the two meshes and the trail's material are
 * made by the first call, and later calls must give the same band. */
int tw_forest_stands_add_floor(struct tw_forest_stands *stands, uint32_t proto, float band);

/* The species weights of stand kind. */
void tw_forest_stand_mix(enum tw_forest_stand_kind kind, float mix[TW_FOREST_SPECIES_COUNT]);

/* Expected triangles of one tree of a stand of kind whose species are drawn
 * from mix (weights >= 0, not all 0): canopy and trunk, sizes as the kind
 * draws them. 0 for bad arguments. */
float tw_forest_stands_tree_triangles(const struct tw_forest_stands *stands,
                                      enum tw_forest_stand_kind kind,
                                      const float mix[TW_FOREST_SPECIES_COUNT]);

/* tw_forest_stands_add() with the species drawn from mix instead of the
 * kind's own and tree_scale (in (0, 4]) times its tree count. */
int tw_forest_stands_add_varied(struct tw_forest_stands *stands, uint32_t proto,
                                enum tw_forest_stand_kind kind, uint64_t stream,
                                const struct tw_forest_area *area,
                                const float mix[TW_FOREST_SPECIES_COUNT], float tree_scale);

/* How high above its area's ground anything a stand of this generator
 * places can reach: its meshes' tops times the largest vertical scale
 * placements use. A bound from the generator's own limits. */
float tw_forest_stands_max_top(const struct tw_forest_stands *stands);

/* ---- built-in tile providers (procedural.c, city-gen.c, forest-gen.c) ------------ */

/* What every built-in provider starts with; provider.user points to the
 * object itself. */
struct tw_tilesets_provider {
    struct tw_tile_provider provider;
    void (*destroy)(struct tw_tilesets_provider *p);   /* frees p and all it owns */
};

/* Fills p for a provider of name whose every cell is content of its own
 * made by generate(user, ...): square tiles of footprint metres, nothing
 * outside the footprint or below y = 0, nothing above top; clusters of
 * max_cluster_triangles. */
void tw_provider_init(struct tw_tile_provider *p, const char *name, float footprint, float top,
                      int (*generate)(void *user, struct tw_cell cell, struct tw_tileset *ts),
                      void *user, uint32_t max_cluster_triangles);

/* Checks what generate() is given (a fresh unfinished tileset with the
 * provider's footprint and no prototype yet); logs a caller's bug naming
 * the cell otherwise. */
int tw_provider_check_tile(const struct tw_tile_provider *provider, const struct tw_log *log,
                           struct tw_cell cell, const struct tw_tileset *ts);

/* city-gen with settings (NULL: the city's defaults; prototypes is ignored):
 * each cell one city block as tw_tilesets_city() makes them, its kind
 * (dense, tallest, low-rise, park, in the shares of the city's default
 * prototypes), footprints, heights, facades and lot layout drawn from
 * tw_tiles_hash(seed, i, j). bound: x, z over the footprint, y from 0 to
 * max_height + 0.25 m. The caller owns *out (tw_tilesets_provider_create()). */
int tw_tilesets_provider_create_city(uint64_t seed, const struct tw_city_settings *settings,
                                     const struct tw_log *log,
                                     struct tw_tilesets_provider **out);

/* forest-gen with settings (NULL: the forest's defaults; prototypes is
 * ignored): each cell one stand over the whole tile, its kind (in the
 * shares of the forest's default prototypes), species mix, tree count and
 * placement drawn from the cell's hash; its trees, rocks and undergrowth
 * from one of a few template sets drawn from seed (copied into the cell's
 * tileset). The floor and the trail along every border as in
 * tw_tilesets_forest(). bound: x, z over the footprint, y from 0 to the
 * tallest template mesh times the largest scale a placement uses. */
int tw_tilesets_provider_create_forest(uint64_t seed, const struct tw_forest_settings *settings,
                                       const struct tw_log *log,
                                       struct tw_tilesets_provider **out);

/* Whether name is one of tw_tilesets_provider_names (false for NULL):
 * registry.c's table. */
bool tw_tilesets_is_provider(const char *name);

/* Whether the built-in tileset or provider called name has the city's
 * streets along every tile border (city, hybrid, city-gen): then sets the
 * footprint and street_width of *streets (may be NULL) to theirs, for
 * tw_traffic_init(). Writes the names that have them, "a, b, c", into
 * names (names_size bytes, may be 0) either way, for messages. */
bool tw_tilesets_streets(const char *name, struct tw_traffic_settings *streets,
                         char *names, size_t names_size);

/* ---- the hybrid tileset (hybrid.c) ---------------------------------------------- */

/* Settings of the hybrid city. Zero-initialisable: zero fields take the
 * defaults of tw_tilesets_hybrid_default_settings(). */
struct tw_hybrid_settings {
    uint32_t prototypes;        /* default 12, at least 8 */
    float footprint;            /* as the city's; default 80 */
    float street_width;         /* as the city's; default 14 */
    float max_height;           /* as the city's; default 90 */
    float green_share;          /* share of prototypes that are parks or wooded
                                 * blocks; default 0.4, in (0, 1) */
    uint32_t max_cluster_triangles; /* default 2048 */
};

void tw_tilesets_hybrid_default_settings(struct tw_hybrid_settings *s);

/* Generates the hybrid tileset for seed: the city's blocks (built by the
 * city's generator) mixed with parks and wooded blocks (the forest's stands
 * inside the block). Streets run along every tile border in every
 * prototype, as in the city. Deterministic; settings may be NULL. The
 * caller owns *out. A host gets it through tw_tilesets_builtin("hybrid"). */
int tw_tilesets_hybrid(uint64_t seed, const struct tw_hybrid_settings *settings,
                       const struct tw_log *log, struct tw_tileset **out);

/* ---- glTF import from an open file (gltf-import.c) ---------------------------------------------- */

/* What several imports share (a manifest's): the bytes they may read and
 * decode together, and the external images they decoded, by file identity,
 * so that a texture named by every file is read and decoded once.
 * Zero-initialise, set the limits if wanted, pass to every import, then
 * tw_gltf_shared_finish(). One thread at a time. */
#define TW_GLTF_MAX_DECODED_BYTES (256ull << 20)       /* RGBA of decoded images */
struct tw_gltf_image_cache;
struct tw_gltf_shared {
    uint64_t max_bytes_read;        /* files, buffers and images; 0: 4 times the first
                                       import's max_file_bytes */
    uint64_t max_decoded_bytes;     /* 0: TW_GLTF_MAX_DECODED_BYTES */
    uint64_t bytes_read;            /* so far */
    uint64_t decoded_bytes;         /* so far */
    struct tw_gltf_image_cache *images; /* gltf-io.c's */
};

/* Frees what the imports left in shared (their decoded images); the scenes
 * they made do not refer to it. Accepts NULL. */
void tw_gltf_shared_finish(struct tw_gltf_shared *shared);

/* tw_gltf_import() of the regular file open as fd (read from where it is,
 * not closed), whose external buffers and images are opened beneath the
 * folder dir_fd (confined-path.h; -1: none allowed). name is used in
 * messages. shared (NULL: this import's own) bounds what this import reads
 * and decodes together with the others that share it. Used by manifests,
 * which open every file beneath their folder once and never by name
 * again. */
int tw_gltf_import_fd(int fd, int dir_fd, const char *name,
                      const struct tw_gltf_settings *settings, struct tw_gltf_shared *shared,
                      const struct tw_log *log, struct tw_gltf_scene **out);

/* The placement "scale uniformly by scale, turn by yaw_degrees about +y
 * (0 keeps +z, 90 turns +z towards +x, as camera yaw in DESIGN.md §9), then
 * move to position" (NULL: the origin) as a row-major 3x4 transform, for
 * tw_gltf_place(). */
void tw_gltf_placement(const float position[3], float yaw_degrees, float scale,
                       float out[12]);

/* ---- implicit tiling's indices (tiles3d-provider.c; the bake's writer uses them) ---- */

/* The number of tiles of a quadtree's levels [0, levels): (4^levels - 1) / 3. */
uint64_t tw_tiles3d_tiles_below(uint32_t levels);
/* The Morton index of (x, y): x's bits in the even places, y's in the odd. */
uint64_t tw_tiles3d_morton(uint32_t x, uint32_t y);

/* ---- the .glb layout of tileworld bake (tiles3d-glb.c) ---------------------------- */

/* Reads the binary glTF file at data (size bytes; borrowed) that `tileworld
 * bake` wrote into ts: every material (tw_tileset_add_material), one mesh
 * per POSITION accessor with its normals (_TW_NORMAL when present, else
 * NORMAL) and its COLOR_0 as tw_mesh.colors, and every child of the root
 * node as an instance of prototype proto (tw_tileset_add_instance) with
 * its matrix, the floats as written. shift NULL: the root node's
 * translation is dropped (the tile's own cell-relative geometry); else each
 * instance is moved by the root's translation plus shift (metres, added in
 * double to each translation). *error (may be NULL): the geometric error
 * the file says it has (asset.extras.geometricError; 0: none). Returns
 * TW_OK, or a negative error with the reason in why: TW_ERR_FORMAT for a
 * file that is no GLB or not in the layout (asset.extras.tileworld.layout
 * "instances"); ts then may hold part of the file. */
int tw_tiles3d_glb_read(const void *data, size_t size, struct tw_tileset *ts, uint32_t proto,
                        const double *shift, double *error, char *why, size_t why_size);
/* Only the geometric error of the binary glTF file at data (size bytes;
 * the binary chunk may be left out): 0 when it says none. TW_ERR_FORMAT
 * for no GLB. */
int tw_tiles3d_glb_error(const void *data, size_t size, double *error);

#endif
