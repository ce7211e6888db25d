/*
 * tilesets: producers of tilesets (DESIGN.md §10): the procedural generators,
 * the built-in providers, glTF import and manifests. Everything here returns a finished
 * struct tw_tileset (tiles/tiles.h) that the caller owns.
 */
#ifndef TW_TILESETS_H
#define TW_TILESETS_H

#include <stddef.h>
#include <stdint.h>

#include "tileworld/tiles.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Settings of the procedural city. Zero-initialisable: zero fields take the
 * defaults of tw_tilesets_city_default_settings(). */
struct tw_city_settings {
    uint32_t prototypes;        /* how many blocks; default 12, at least 8 */
    float footprint;            /* tile side in metres (square tiles); default 80 */
    float street_width;         /* full street width; half lies in each tile; default 14 */
    float max_height;           /* tallest building, metres; default 90 */
    uint32_t max_cluster_triangles; /* passed to tw_tileset_finish(); default 2048 */
};

void tw_tilesets_city_default_settings(struct tw_city_settings *s);

/* Generates the city tileset for seed: blocks of buildings of varied
 * footprint and height with window and ledge geometry, streets along every
 * tile border (a camera at local x = 0 or z = 0, eye height, stands on a
 * street). Deterministic: the same seed and settings give the same tileset,
 * bit for bit. settings may be NULL. The caller owns *out. */
int tw_tilesets_city(uint64_t seed, const struct tw_city_settings *settings,
                     const struct tw_log *log, struct tw_tileset **out);

/* Names of the built-in tilesets, NULL-terminated: "city", "forest",
 * "hybrid". */
extern const char *const tw_tilesets_builtin_names[];

/* Builds the built-in tileset called name with default settings but
 * max_cluster_triangles (0: the generator's default): "city"
 * (tw_tilesets_city()), "forest" (tw_tilesets_forest()) or "hybrid", the
 * city's blocks mixed with parks and wooded blocks (the forest's stands
 * inside the block), streets along every tile border as in the city;
 * deterministic like them. Returns TW_ERR_INVALID, with a message, for an
 * unknown name. The caller owns *out. */
int tw_tilesets_builtin(const char *name, uint64_t seed,
                        uint32_t max_cluster_triangles,
                        const struct tw_log *log, struct tw_tileset **out);

/* ---- glTF import and manifests ---- */

/* Limits of one glTF import. Zero-initialisable: zero fields take the
 * defaults of tw_gltf_default_settings(). */
struct tw_gltf_settings {
    uint64_t max_file_bytes;    /* the file plus its external buffers; default 256 MiB */
    uint64_t max_triangles;     /* triangles the scene draws (every instance); default 10 M */
};

void tw_gltf_default_settings(struct tw_gltf_settings *s);

/* One glTF mesh primitive as an indexed triangle list (strips and fans are
 * converted), in the glTF mesh's own coordinates. */
struct tw_gltf_primitive {
    float *positions;           /* xyz per vertex, vertex_count * 3 */
    float *normals;             /* xyz per vertex, or NULL when the file has none usable */
    uint32_t *indices;          /* three per triangle, triangle_count * 3 */
    uint32_t vertex_count;
    uint32_t triangle_count;    /* >= 1 */
    uint32_t material;          /* index into tw_gltf_scene.materials */
    struct tw_box box;
};

/* A glTF mesh that the scene draws: primitives [first_primitive,
 * first_primitive + primitive_count). */
struct tw_gltf_mesh {
    uint32_t first_primitive;
    uint32_t primitive_count;
};

/* A node that draws a mesh, its hierarchy flattened into one transform. */
struct tw_gltf_instance {
    uint32_t mesh;              /* index into tw_gltf_scene.meshes */
    float transform[12];        /* affine, row-major 3x4, mesh -> scene coordinates */
};

/* An imported glTF scene: read-only plain data, owned by whoever imported
 * it and freed with tw_gltf_scene_destroy(). Only the meshes that the scene
 * draws are kept; a mesh used by several nodes is one mesh, several
 * instances. */
struct tw_gltf_scene {
    char *source;               /* the file name given to the importer */
    struct tw_gltf_primitive *primitives;
    uint32_t primitive_count;
    struct tw_gltf_mesh *meshes;
    uint32_t mesh_count;
    struct tw_material *materials;  /* the file's, a grey default if needed, then colours
                                       baked from base-colour textures */
    uint32_t material_count;
    struct tw_gltf_instance *instances;
    uint32_t instance_count;
    uint64_t vertex_count;      /* over the meshes */
    uint64_t unique_triangles;  /* over the meshes */
    uint64_t triangle_count;    /* drawn: over the instances */
    struct tw_box bounds;       /* of every instance, scene coordinates */
};

/* Imports the default scene (else scene 0, else every root node) of the
 * .gltf or .glb file at path (binary or JSON is told by the content; only a
 * regular file is read: a FIFO is refused, never waited on). Buffers and
 * images in external files must lie inside the file's folder; they are
 * opened beneath it (confined-path.h) and their URIs decoded as RFC 3986
 * says ('+' is a plus sign). Textures are not kept: a PNG base-colour
 * texture is sampled at each triangle's centroid (through its
 * KHR_texture_transform) and its primitive split into one material per
 * colour. An image is decoded once however many images, textures or
 * materials name its bytes, and its size is read from its header first: one
 * that would decode to more than 64 MiB, or take the import's decoded images
 * beyond 256 MiB, is not decoded. A texture that cannot be used leaves the
 * base colour, with a warning (eight at most, then one line counting the
 * rest). Every reference, accessor range and alignment, index (below the
 * vertex count, never the restart value), sparse index order and node
 * transform is checked, node hierarchies must be trees (no cycles, one parent
 * per node). Triangles (lists, strips or fans) are drawn; points and lines
 * are skipped with one warning. The document must be glTF 2.x: asset.version
 * "2.<minor>", and an asset.minVersion of at most "2.0". KHR_mesh_quantization
 * is supported (integer positions, normals and texture coordinates,
 * dequantised by the node transforms); a required extension that is not
 * supported (Draco, meshopt, GPU instancing, any unknown name) is refused by
 * name; required extensions that change only materials, lights or image
 * formats are accepted. Coordinates are bounded (tiles.h): node values and
 * mesh-local positions within +-TW_TILES_MAX_MESH_COORD, every placed mesh
 * within +-TW_TILES_MAX_COORD. Cost is bounded by the input, checked before
 * it is spent: every check is linear, and each accessor is read once; a
 * document whose JSON would take more than 64 MiB + 32 bytes per byte of
 * JSON (estimated before parsing), whose mesh accessors hold more than
 * 64 MiB + 4 bytes per byte of file and buffers to check (accessors that
 * overlap), or whose meshes would take more than 64 MiB + 32 bytes per byte
 * of file and buffers to convert (accessors without a buffer view) is
 * refused. settings may be NULL. On
 * bad input returns TW_ERR_FORMAT, TW_ERR_IO or TW_ERR_LIMIT and logs one
 * error line "<path>: <element>: <reason>" (text from the file escaped,
 * tiles.h tw_log_escape()), e.g.
 * "a.gltf: nodes[2].children[0]: nodes[0] is an ancestor of nodes[2] (a cycle)".
 * The caller owns *out. */
int tw_gltf_import(const char *path, const struct tw_gltf_settings *settings,
                   const struct tw_log *log, struct tw_gltf_scene **out);

/* The same from size bytes at data (only read during the call). name is used
 * in messages; base_dir is the folder of external buffers, NULL to refuse
 * them (then nothing but data is read). */
int tw_gltf_import_memory(const void *data, size_t size, const char *name,
                          const char *base_dir, const struct tw_gltf_settings *settings,
                          const struct tw_log *log, struct tw_gltf_scene **out);

/* Frees an imported scene; accepts NULL. */
void tw_gltf_scene_destroy(struct tw_gltf_scene *scene);

/* Where a scene's data went in a tileset: primitive p is tileset mesh
 * first_mesh + p, scene material m is tileset material first_material + m. */
struct tw_gltf_binding {
    uint32_t first_mesh;
    uint32_t first_material;
};

/* Adds the scene's primitives as meshes and its materials to the unfinished
 * tileset ts, once; place it as often as wanted with tw_gltf_place(). */
int tw_gltf_bind(const struct tw_gltf_scene *scene, struct tw_tileset *ts,
                 struct tw_gltf_binding *out);

/* Adds one instance per (scene instance, primitive) to prototype proto of
 * ts, under placement (row-major 3x4, tile-local; NULL for identity) applied
 * after the scene's own transforms. The meshes stay shared. */
int tw_gltf_place(const struct tw_gltf_scene *scene, const struct tw_gltf_binding *binding,
                  struct tw_tileset *ts, uint32_t proto, const float placement[12]);

/* Tileset manifests: a JSON file that composes glTF files into prototypes.
 * The format is documented at the top of tilesets/manifest.c (and in the
 * README). */
struct tw_manifest_settings {
    uint32_t max_cluster_triangles; /* 0: the manifest's, else 2048 */
    struct tw_gltf_settings gltf;   /* limits of each glTF file; zero: defaults */
};

/* Loads the manifest at path (a regular file: a FIFO is refused, never
 * waited on) and every glTF file it names (paths relative to the manifest's
 * folder, which they may not leave: opened beneath it), with settings (NULL:
 * defaults), into a finished tileset whose per-frame cost is bounded
 * (tiles.h: weights and scales in [1e-6, 1e6], content within reach of its
 * tile and at most TW_TILES_MAX_SPAN footprints wide, at most
 * TW_TILES_MAX_CELLS_IN_VIEW cells in view at the default view distance).
 * Its glTF files are imported once each, and together they may read at
 * most 4 times gltf.max_file_bytes and decode at most 256 MiB of images (an
 * image file named by several is decoded once); a prototype may draw at most
 * gltf.max_triangles triangles, the tileset's prototypes together 10 times
 * that. On bad input returns a negative tw_error and logs one error line
 * "<manifest>: <place, e.g. prototypes[2].objects[0].gltf>: <reason>"
 * ("<manifest>: no such file" for a missing one). The caller owns *out. */
int tw_tilesets_load_manifest(const char *path, const struct tw_manifest_settings *settings,
                              const struct tw_log *log, struct tw_tileset **out);
/* The same from size bytes of JSON at text; name is used in messages and
 * default names, base_dir is the folder that file names resolve in. */
int tw_tilesets_parse_manifest(const char *text, size_t size, const char *name,
                               const char *base_dir,
                               const struct tw_manifest_settings *settings,
                               const struct tw_log *log, struct tw_tileset **out);

/* ---- forest ---- */

/* Settings of the procedural forest. Zero-initialisable: zero fields take
 * the defaults of tw_tilesets_forest_default_settings(). */
struct tw_forest_settings {
    uint32_t prototypes;        /* how many stands; default 10, at least 8 */
    float footprint;            /* tile side in metres (square tiles); default 80, in [40, 1000] */
    float density;              /* scales every stand's tree count; default 1, in [0.25, 2] */
    float path_clearance;       /* half-width of the clear trail on every tile border,
                                 * metres; default 1, in [0.1, 5] */
    uint32_t max_cluster_triangles; /* passed to tw_tileset_finish(); default 2048 */
};

void tw_tilesets_forest_default_settings(struct tw_forest_settings *s);

/* Generates the forest tileset for seed: stands of trees (conifers of
 * stacked frusta, lumpy broadleaves, birches; each tree an instance of a
 * shared species x size mesh, turned about y and scaled), undergrowth baked
 * into shared patch meshes, rocks and logs: many weak occluders that close
 * up only together. Stands vary: dense, mixed, thin, a clearing, a rocky
 * one. Along every tile border runs a trail: within path_clearance of a
 * border nothing stands between 0.05 m and 2.5 m above the ground (no
 * trunk, bush or low branch), and everything stays inside the footprint.
 * Deterministic: the same seed and settings give the same tileset, bit for
 * bit. settings may be NULL. The caller owns *out. */
int tw_tilesets_forest(uint64_t seed, const struct tw_forest_settings *settings,
                       const struct tw_log *log, struct tw_tileset **out);

/* ---- tile providers: city-gen and forest-gen (DESIGN.md §12) ---- */

/* A built-in tile provider: every cell's content generated from the cell's
 * hash, no two cells alike, at the triangle density of the fixed tileset
 * it is named after, with its footprint and its streets or trails along
 * every tile border (the built-in camera paths work on it). Owns what its
 * tw_tile_provider points to: the seed, the settings, read-only templates.
 * Every cell is TW_TILE_OWN (content is NULL, shared is NULL). */
struct tw_tilesets_provider;

/* Names of the built-in providers, NULL-terminated: "city-gen", "forest-gen". */
extern const char *const tw_tilesets_provider_names[];

/* Creates the built-in provider called name for seed, with default settings
 * but max_cluster_triangles (0: 2048). city-gen: each cell one city block
 * as tw_tilesets_city() makes them, its kind (dense, tallest, low-rise,
 * park, in the shares of the city's default prototypes), footprints,
 * heights, facades and lot layout drawn from tw_tiles_hash(seed, i, j).
 * forest-gen: each cell one stand over the whole tile, its kind, species
 * mix, tree count and placement drawn from the cell's hash, with the floor
 * and the trail along every border of tw_tilesets_forest(). Returns
 * TW_ERR_INVALID, with a message, for a name not in
 * tw_tilesets_provider_names. The caller owns *out and must keep it
 * until every world using its tw_tile_provider is gone. log (may be NULL)
 * is copied: its callback must outlive the provider and may be called from
 * generate(), on a worker thread, when a world hands it a wrong tileset
 * (the message names the cell). */
int tw_tilesets_provider_create(const char *name, uint64_t seed,
                                uint32_t max_cluster_triangles,
                                const struct tw_log *log,
                                struct tw_tilesets_provider **out);

/* The provider to hand to a world: borrowed from p, valid until p is
 * destroyed. Its generate() may run on any number of threads at once (it
 * only reads p) and is a pure function of the cell: the same cell gives
 * the same tile, bit for bit. NULL for NULL. */
const struct tw_tile_provider *tw_tilesets_provider_get(const struct tw_tilesets_provider *p);

/* Frees p and everything it owns; accepts NULL. */
void tw_tilesets_provider_destroy(struct tw_tilesets_provider *p);

/* ---- a baked 3D Tiles tileset streamed back (HTTP or file) ---- */

/* How the 3D Tiles provider fetches. Zero-initialisable: zero fields take
 * the defaults of tw_tiles3d_default_settings(). */
struct tw_tiles3d_settings {
    const char *cache_dir;          /* an on-disk cache of bodies with their ETag, made if
                                       missing, with its parents (copied at creation); NULL: none */
    uint64_t cache_max_bytes;       /* the cache's files together; beyond it the oldest go;
                                       default 1 GiB */
    uint32_t connect_timeout_ms;    /* a connection's setup; default 5000 */
    uint32_t timeout_ms;            /* a whole request; default 30000 */
    uint32_t retries;               /* more attempts after a failure that may pass (5xx, 408,
                                       429, a timeout, a connection error); default 3;
                                       TW_TILES3D_NO_RETRY: none */
    uint32_t retry_delay_ms;        /* the first back-off, doubled at each retry; default 100 */
    uint32_t max_cluster_triangles; /* for the tiles; default 2048 */
    struct tw_gltf_settings gltf;   /* limits of each tile's glTF; zero: defaults */
};

#define TW_TILES3D_NO_RETRY UINT32_MAX

void tw_tiles3d_default_settings(struct tw_tiles3d_settings *s);

/* What a 3D Tiles provider has done so far. */
struct tw_tiles3d_stats {
    uint64_t requests;      /* attempts sent (each retry is one) */
    uint64_t bytes;         /* body bytes received */
    uint64_t cache_hits;    /* bodies served from the cache */
    uint64_t not_modified;  /* 304 answers to If-None-Match */
    uint64_t retries;       /* attempts after a failure that may pass */
    uint64_t failures;      /* requests given up: a 404, another 4xx, retries spent */
    uint64_t stale;         /* bodies served from the cache because the server could not
                               answer (a 5xx, a timeout, a lost connection, after the
                               retries), as HTTP's stale-if-error; not in failures */
    uint64_t cells;         /* cells' tiles read (generate()) */
    uint64_t blocks;        /* tiles of coarser levels read (generate_level()) */
};

/* A tile provider that streams a tileset written by `tileworld bake` (3D
 * Tiles 1.1, implicit quadtree tiling, tileset.json's
 * extras.tileworld giving the footprint, the rectangle of cells and the
 * bound) from url: http://, https:// or file:// to its tileset.json. */
struct tw_tiles3d_provider;

/* Fetches tileset.json and the subtrees that say which cells have
 * content, and makes the provider: content() answers TW_TILE_EMPTY outside
 * the baked rectangle and for cells without content, TW_TILE_OWN for the
 * others (a table lookup); generate() GETs the cell's
 * content/L/X/Y.glb on the calling worker thread and imports it (its
 * geometry is tile-local: the node's translation, the cell's offset in
 * the rectangle, is dropped). A bake with coarser levels (`bake --levels
 * N`, extras.tileworld.levels) gives the provider levels of its own
 * (tw_tile_provider.levels, generate_level()): the bake's levels whose
 * blocks line up with the world's (its corner a multiple of 2^k cells;
 * a warning names the levels left out), which a world with levels of
 * detail draws far away. How many fetches run at once is how many
 * workers the world has (tw_world_settings.workers): the provider adds no
 * threads. A tile that cannot be had (a 404 of an available tile, a
 * 4xx, retries spent, a malformed glb) is refused with its cause
 * (tw_tileset_fail(): "GET URL: HTTP 500 after 4 attempts"), and the world
 * asks again on its schedule. settings may be NULL. Fails with
 * TW_ERR_INVALID (a URL of another scheme, a tileset not baked by
 * tileworld, a build without libcurl), TW_ERR_IO (it cannot be fetched) or
 * TW_ERR_FORMAT, with one error line. log (may be NULL) is copied: its
 * callback must outlive the provider and may be called from worker
 * threads. The caller owns *out and keeps it until every world using it
 * is gone. Process-wide state: curl_global_init(), once. */
int tw_tiles3d_provider_create(const char *url, const struct tw_tiles3d_settings *settings,
                               const struct tw_log *log, struct tw_tiles3d_provider **out);

/* The provider to hand to a world: borrowed from p, valid until p is
 * destroyed. NULL for NULL. */
const struct tw_tile_provider *tw_tiles3d_provider_get(const struct tw_tiles3d_provider *p);

/* The counters so far into *out (any thread; zeroes for NULL p). */
void tw_tiles3d_provider_stats(const struct tw_tiles3d_provider *p,
                               struct tw_tiles3d_stats *out);

/* Frees p; accepts NULL. Transfers still in flight (a world's worker left
 * behind at tw_world_destroy's shutdown timeout) are cancelled, and what
 * they use is freed when the last of them returns. */
void tw_tiles3d_provider_destroy(struct tw_tiles3d_provider *p);

/* ---- traffic: moving cars for the city ---- */

/* How many models tw_tilesets_car_models() makes. */
#define TW_TRAFFIC_CAR_MODELS 12u
/* The largest car of those models, metres: its length (along z) and width
 * (along x). */
#define TW_TRAFFIC_CAR_LENGTH 4.8f
#define TW_TRAFFIC_CAR_WIDTH 1.95f

/* Builds a finished tileset of TW_TRAFFIC_CAR_MODELS car models for
 * runtime.h's object_models: a saloon, a hatchback and a van (a body, a
 * cabin and two axles of wheels: 36 triangles each), each in four colours.
 * Model-local coordinates: the origin on the ground at the car's centre, y
 * up, +z forward; every model within TW_TRAFFIC_CAR_LENGTH x
 * TW_TRAFFIC_CAR_WIDTH and 2 m high. Footprint 8 x 8 m (a nominal one:
 * objects have no cell of their own). Deterministic. The caller owns
 * *out. */
int tw_tilesets_car_models(const struct tw_log *log, struct tw_tileset **out);

/* Where the cars drive. Zero-initialisable: zero fields take the defaults
 * of tw_traffic_default_settings() (the centre cell (0, 0) and seed 0 are
 * values, not defaults). */
struct tw_traffic_settings {
    uint64_t seed;              /* each car's model, lane, speed and place in it */
    uint32_t cars;              /* how many; 0..TW_TRAFFIC_MAX_CARS; default 0 */
    uint32_t models;            /* car k's model is one of [0, models); default
                                   TW_TRAFFIC_CAR_MODELS */
    float footprint;            /* the city's tile side (tw_city_settings); default 80 */
    float street_width;         /* the city's full street width; default 14 */
    struct tw_cell centre;      /* the square's centre: this cell's origin corner; i and j
                                   within +-2^62 */
    float radius_m;             /* half the square's side, rounded up to whole cells;
                                   default 600, in [1, 100000] */
    float speed_mps;            /* mean speed, metres a second; default 10, in (0, 100] */
};

#define TW_TRAFFIC_MAX_CARS 1000000u

void tw_traffic_default_settings(struct tw_traffic_settings *s);

/* Traffic on the city's streets (tw_tilesets_city(), hybrid, city-gen: a
 * street along every tile border, its road within
 * tw_traffic.road_half_width of the border, sidewalks and blocks beyond).
 * Cars drive in the square of cells centre +- half_cells, on every street
 * line inside it, both ways along x and along z: two lanes a street,
 * right-hand traffic, each lane_offset from the street's centre line. A car
 * that leaves the square on one side comes back on the other. The lanes
 * share the cars out (car k in lane k mod lanes), each lane's cars evenly
 * spaced and driving at the lane's own speed (0.8 to 1.2 times
 * speed_mps), so cars of one lane never come closer than
 * lane_length / cars of the lane; cars crossing at a junction are not
 * kept apart (there are no traffic lights). Plain data; fill it with
 * tw_traffic_init(). */
struct tw_traffic {
    struct tw_traffic_settings settings;    /* resolved */
    int64_t half_cells;         /* n = ceil(radius_m / footprint): cells centre - n ..
                                   centre + n - 1 along i and j */
    uint32_t lanes;             /* 8 n: 2 n street lines each way, two lanes each */
    double lane_length;         /* 2 n footprint, metres */
    float road_half_width;      /* the road (kerb to kerb) spans this either side of a
                                   tile border */
    float lane_offset;          /* a lane's centre line from the street's */
    uint32_t line_stride;       /* the lanes' street lines are taken in this stride */
};

/* Where a car is: the fields of runtime.h's struct tw_object (tilesets sit
 * below the runtime; a host copies them over): its centre on the ground,
 * pos normalised (0 <= local < footprint), local[1] = 0 (the road); yaw in
 * degrees (0: driving along +z, 90: +x, 180: -z, 270: -x), as the object's
 * yaw turns the model's +z; and its model. */
struct tw_traffic_car {
    struct tw_world_pos pos;
    float yaw;
    uint32_t model;
};

/* Validates settings (NULL: all defaults; bad ones get a message naming
 * the field, TW_ERR_INVALID) and fills *t. */
int tw_traffic_init(struct tw_traffic *t, const struct tw_traffic_settings *settings,
                    const struct tw_log *log);

/* Car car (< settings.cars) at seconds (finite; negative is the past) into
 * *out: a pure function of (*t, car, seconds), the same bits on every run.
 * Its footprint (TW_TRAFFIC_CAR_LENGTH x TW_TRAFFIC_CAR_WIDTH at most) lies
 * on the road, inside its lane. Returns TW_ERR_INVALID for a car out of
 * range or a time that is not finite (out untouched). Thread-safe: only
 * reads *t. */
int tw_traffic_place(const struct tw_traffic *t, uint32_t car, double seconds,
                     struct tw_traffic_car *out);

#ifdef __cplusplus
}
#endif

#endif
