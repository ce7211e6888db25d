/*
 * tiles: the bottom module of tileworld.
 *
 * Cells of the infinite grid and camera-relative coordinates (DESIGN.md §3),
 * the tileset model (prototypes made of instances of shared meshes, split into
 * draw clusters), selection (cell -> prototype, a pure function), error codes
 * and the per-context logger that every module above uses.
 *
 * Threading: nothing here holds global state; distinct objects may be used
 * from distinct threads.
 */
#ifndef TW_TILES_H
#define TW_TILES_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---- errors and logging ------------------------------------------------ */

enum tw_error {
    TW_OK = 0,
    TW_ERR_INVALID = -1,    /* an argument or an input is malformed */
    TW_ERR_NOMEM = -2,      /* an allocation failed */
    TW_ERR_IO = -3,         /* a file could not be read or written */
    TW_ERR_FORMAT = -4,     /* a file's content is malformed */
    TW_ERR_LIMIT = -5,      /* an input exceeds a configured limit */
    TW_ERR_GL = -6,         /* OpenGL failed or lacks a needed feature */
    TW_ERR_EMBREE = -7,     /* Embree reported an error */
    TW_ERR_STATE = -8,      /* the call is not valid in the object's state */
};

/* A static English string for an error code; never NULL. */
const char *tw_error_to_str(int err);

enum tw_log_level {
    TW_LOG_ERROR = 0,
    TW_LOG_WARN = 1,
    TW_LOG_INFO = 2,
    TW_LOG_DEBUG = 3,
};

/* A logger: a callback and its user pointer. A zeroed logger discards
 * messages. Owned by whoever embeds it; the callback may be called from the
 * thread that calls into the object the logger was given to. */
struct tw_log {
    void (*fn)(void *user, enum tw_log_level level, const char *msg);
    void *user;
};

/* A logger that writes "tileworld: <level>: msg" lines to stderr, for
 * messages at or below the level passed as user (cast from intptr_t). */
void tw_log_stderr(void *user, enum tw_log_level level, const char *msg);

/* ---- boxes -------------------------------------------------------------- */

/* Axis-aligned box in metres. An empty box has min > max. */
struct tw_box {
    float min[3];
    float max[3];
};

/* ---- cells and positions (DESIGN §3) ------------------------------------ */

/* One square of the infinite grid: i runs along +x, j along +z. */
struct tw_cell {
    int64_t i;
    int64_t j;
};

/* A world position: a cell plus a float offset inside it (metres; y is
 * height above the ground). Never an absolute position in float. */
struct tw_world_pos {
    struct tw_cell cell;
    float local[3];
};

/* Moves whole footprints out of p->local[0] (x) and p->local[2] (z) into the
 * cell, so that 0 <= local[0] < w and 0 <= local[2] < d afterwards. Works for
 * any finite local offset; computed in double. Returns TW_ERR_INVALID (p
 * unchanged) if an offset is not finite or the cell would overflow. */
int tw_tiles_normalize(struct tw_world_pos *p, float w, float d);

/* ---- limits: what a frame can afford ------------------------------------------ */

/* Tile content lives within this many metres of its tile's origin: every
 * tile-local coordinate (an instance's placed vertices, its box, a
 * prototype's box, the common box) and every coordinate of an imported
 * scene. 100 km: floats still resolve 8 mm there, and sums and differences
 * of such values (box centres and extents in Embree's SAH binning, plane
 * distances in the frustum tests, the cell scan) stay far from overflow. */
#define TW_TILES_MAX_COORD 1.0e5f
/* Mesh-local positions may be larger (a mesh modelled in millimetres and
 * scaled by 0.001 when placed); the placed result must fit TW_TILES_MAX_COORD.
 * Transform coefficients (rotation and scale terms) are bounded by
 * TW_TILES_MAX_COORD too. */
#define TW_TILES_MAX_MESH_COORD 1.0e7f
/* The common box spans at most this many footprints along x and along z:
 * content that overhangs its cell further would make every tile overlap
 * dozens of others (overdraw) and every frame consider cells far outside the
 * view distance. */
#define TW_TILES_MAX_SPAN 8.0f
/* ---- the tileset model ---------------------------------------------------- */

/* A material: one base colour, linear RGBA in [0, 1]. */
struct tw_material {
    float base_color[4];
};

/* A shared triangle mesh, in mesh-local coordinates. After
 * tw_tileset_finish() its triangles without area are gone (triangle_count
 * may then be 0) and the others are reordered so that each of its parts is a
 * contiguous index range. */
struct tw_mesh {
    float *positions;     /* xyz per vertex, vertex_count * 3 */
    float *normals;       /* xyz per vertex, vertex_count * 3 */
    uint32_t *indices;    /* three per triangle, triangle_count * 3 */
    uint8_t *colors;      /* RGBA per vertex, vertex_count * 4, or NULL (white): set by
                             tw_tileset_finish() on a merged mesh, whose instances' materials
                             it holds; drawn multiplied by the instance's material */
    uint32_t vertex_count;
    uint32_t triangle_count;
    uint32_t first_part;  /* index into tw_tileset.parts */
    uint32_t part_count;
    struct tw_box box;
};

/* A spatially coherent piece of a mesh: triangles [first_triangle,
 * first_triangle + triangle_count) of mesh. */
struct tw_mesh_part {
    uint32_t mesh;
    uint32_t first_triangle;
    uint32_t triangle_count;
    struct tw_box box;    /* mesh-local */
};

/* One placement of a shared mesh inside a prototype. */
#define TW_INSTANCE_NONE UINT32_MAX
struct tw_instance {
    uint32_t mesh;
    uint32_t material;
    float transform[12];  /* affine, row-major 3x4, mesh-local -> tile-local */
    struct tw_box box;    /* tile-local */
    uint32_t merged_into; /* TW_INSTANCE_NONE, or (after tw_tileset_finish) the instance
                             of a merged mesh that draws this one's triangles: such an
                             instance has no clusters of its own */
    bool merged;          /* made by tw_tileset_finish(): an identity placement of a merged
                             mesh, drawing the instances merged into it */
};

/* The unit that the BVH indexes and the renderer draws: one part of one
 * instance (DESIGN §1). */
struct tw_cluster {
    uint32_t instance;    /* index into the prototype's instances */
    uint32_t part;        /* index into tw_tileset.parts */
    uint32_t triangle_count;
    struct tw_box box;    /* tile-local */
};

struct tw_prototype {
    char name[48];
    float weight;                 /* selection weight, > 0 */
    struct tw_instance *instances;
    uint32_t instance_count;
    struct tw_cluster *clusters;  /* built by tw_tileset_finish() */
    uint32_t cluster_count;
    uint64_t triangle_count;
    struct tw_box box;            /* tile-local */
};

/* A tileset: built with the calls below, then frozen by tw_tileset_finish().
 * Readers use the fields directly through a const pointer; only the builder
 * calls write them. Tile-local coordinates put the cell's origin corner at
 * (0, 0, 0), the tile spanning [0, footprint[0]] x [0, footprint[1]] in x, z. */
struct tw_tileset {
    char name[64];
    float footprint[2];           /* W (along x), D (along z), metres */
    struct tw_material *materials;
    uint32_t material_count;
    struct tw_mesh *meshes;
    uint32_t mesh_count;
    struct tw_mesh_part *parts;
    uint32_t part_count;
    struct tw_prototype *prototypes;
    uint32_t prototype_count;
    struct tw_box common_box;     /* union of every prototype's box */
    uint32_t max_cluster_triangles;
    uint32_t merge_triangles;     /* set before tw_tileset_finish(): instances whose mesh has
                                     fewer triangles are merged (0: the default,
                                     TW_TILESET_MERGE_TRIANGLES; 1: none is) */
    bool finished;
};

/* Creates an empty tileset with footprint w x d metres (both > 0 and finite).
 * The caller owns *out and frees it with tw_tileset_destroy(). */
int tw_tileset_create(const char *name, float w, float d,
                      struct tw_tileset **out);
/* Frees a tileset; accepts NULL and unfinished tilesets. */
void tw_tileset_destroy(struct tw_tileset *ts);

/* Adds a material; returns its index (>= 0) or a negative error. */
int tw_tileset_add_material(struct tw_tileset *ts, const float rgba[4]);

/* Adds a mesh, copying the arrays. normals may be NULL: then smooth
 * area-weighted normals are computed. Every index must be < vertex_count and
 * every position finite and within +-TW_TILES_MAX_MESH_COORD (TW_ERR_LIMIT
 * beyond). Returns the mesh index (>= 0) or a negative error. */
int tw_tileset_add_mesh(struct tw_tileset *ts, const float *positions,
                        const float *normals, uint32_t vertex_count,
                        const uint32_t *indices, uint32_t triangle_count);

/* Adds an empty prototype; returns its index or a negative error. */
int tw_tileset_add_prototype(struct tw_tileset *ts, const char *name,
                             float weight);

/* Places mesh with material inside prototype proto under transform
 * (row-major 3x4, NULL for identity): finite, every coefficient within
 * +-TW_TILES_MAX_COORD (TW_ERR_LIMIT beyond), and the mesh's box placed by it
 * within +-TW_TILES_MAX_COORD (TW_ERR_LIMIT). Returns the instance index or a
 * negative error. */
int tw_tileset_add_instance(struct tw_tileset *ts, uint32_t proto,
                            uint32_t mesh, uint32_t material,
                            const float transform[12]);

/* Freezes the tileset. First it drops every triangle without area (its
 * height over its longest edge within FLT_EPSILON of that edge: collinear
 * or coincident corners), which covers nothing but which a rasteriser may
 * still give stray fragments at any depth. Then, with
 * max_cluster_triangles > 0, the small instances of each prototype (mesh
 * of fewer than merge_triangles triangles) are merged, whatever their
 * materials: when there are two or more, their vertices are transformed
 * into tile-local space (normals by the transform's linear part, as the
 * renderer's shader does) into one new mesh whose vertices carry their
 * instance's material as a colour, placed by a new identity instance of a
 * white material (added if the tileset has none); the small instances stay
 * in the list, marked merged_into, and get no clusters (a draw call then
 * carries many instances instead of a few triangles, and the merged mesh's
 * clusters are split by place, not by material); baking copies what
 * instancing shares, so the merged meshes of a tileset hold
 * TW_TILESET_MERGE_BYTES at most (instances beyond stay instanced). Then it
 * splits every mesh into parts of at most
 * max_cluster_triangles triangles (0: never split) by recursive median
 * splits along the longest axis, computes every box, the clusters of every
 * prototype and the common box. Fails on a tileset with no prototype, or
 * with an empty prototype: one with no instance or with no triangle that
 * has an area (TW_ERR_INVALID); and on one whose common box spans more than
 * TW_TILES_MAX_SPAN footprints along x or z (TW_ERR_LIMIT). */
#define TW_TILESET_MERGE_TRIANGLES 64u
#define TW_TILESET_MERGE_BYTES (16ull << 20)
int tw_tileset_finish(struct tw_tileset *ts, uint32_t max_cluster_triangles);

/* ---- selection ------------------------------------------------------------ */

/* A host's world generator: returns the prototype shown at cell, which must
 * be < the tileset's prototype_count, or TW_TILE_EMPTY for a cell that shows
 * nothing. Must be a pure function of the cell. */
typedef uint32_t (*tw_select_fn)(void *user, struct tw_cell cell);

/* How cells choose prototypes. Zero-initialisable: seed 0, not periodic,
 * the weighted hash selection. */
struct tw_selection {
    uint64_t seed;
    int64_t repeat;        /* > 0: periodic with this period in i and j */
    tw_select_fn fn;       /* non-NULL: a host callback replaces the hash */
    void *user;            /* passed to fn; owned by the host */
};

/* A 64-bit mix of (seed, i, j), the hash behind selection; exposed for
 * generators that want the same stream. */
uint64_t tw_tiles_hash(uint64_t seed, int64_t i, int64_t j);

/* One cluster of one tile: what a frame drew, or a set to draw. */
struct tw_drawn_cluster {
    struct tw_cell cell;
    uint32_t prototype;                 /* the tile's content: a prototype of the tileset, or
                                           of the provider's shared one; a generated
                                           tile's own content is numbered after them */
    uint32_t cluster;                   /* of the level drawn */
    uint32_t level;                     /* 0: full detail; k: the content's k-th coarser
                                           level of detail (DESIGN §17) */
};

/* ---- tile providers (DESIGN §12) ------------------------------------------------- */

/* What tw_tile_provider.content() answers for a cell with content of its own. */
#define TW_TILE_OWN UINT32_MAX
/* What content() or a selection answers for a cell that shows nothing (sea,
 * void): no tile is made, nothing is drawn or logged there, and visibility
 * spreads through the cell (its box is still queried like any other: what
 * lies behind it is seen through it). */
#define TW_TILE_EMPTY (UINT32_MAX - 1u)
/* What generate() returns for a cell it finds empty once it looks (the
 * tileset it was given is then ignored): the same as TW_TILE_EMPTY, found
 * on a worker; no error, no refusal. */
#define TW_GENERATE_EMPTY 1

/* The most coarser levels a tw_tile_provider may have of its own (blocks
 * of up to 2^11 x 2^11 cells). */
#define TW_PROVIDER_MAX_LEVELS 11u

/* A world generator: what each cell holds, made on demand. A fixed tileset
 * with a selection is the special case in which every cell's content is
 * shared (one of the tileset's prototypes).
 *
 * The pointers and the provider itself are borrowed by the world that uses
 * it and must outlive it. */
struct tw_tile_provider {
    const char *name;                   /* for messages */
    float footprint[2];                 /* W, D metres: the grid's cells */
    /* A tile-local box holding every tile the provider can ever produce: the
     * common box that tile queries draw (DESIGN §4), declared up front
     * because a query must be conservative before the tile behind it
     * exists. A generated tile that exceeds it is refused (logged with its
     * cell, counted, not drawn). */
    struct tw_box bound;
    /* Prototypes that cells may share (may be NULL); finished, with the
     * provider's footprint; every prototype inside bound. */
    const struct tw_tileset *shared;
    /* What cell shows: an index into shared's prototypes, TW_TILE_OWN for
     * content of its own made by generate(), or TW_TILE_EMPTY (nothing). Called on the render thread,
     * often (every cell in view, every frame): must be cheap. Must be a pure
     * function of the cell until the host invalidates it; an answer that
     * changes for a cached cell is taken as an invalidation. NULL: every
     * cell is TW_TILE_OWN. */
    uint32_t (*content)(void *user, struct tw_cell cell);
    /* Writes cell's own content into ts: a fresh, unfinished tileset with
     * the provider's footprint and no prototype yet, filled through the
     * builder calls (tw_tileset_add_material, _add_mesh, one
     * _add_prototype, _add_instance); the library finishes it (clusters of
     * max_cluster_triangles) and builds its BVH. Called on worker threads,
     * concurrently for different cells: must be thread-safe, and a pure
     * function of the cell until invalidated. Returns TW_OK;
     * TW_GENERATE_EMPTY for a cell that holds nothing; or a negative error:
     * the cell then shows nothing, the world logs it with its cell and the
     * message the provider logged (see tw_tile_event), counts it, and asks
     * again later (tw_world_settings.retry_after_frames).
     * NULL only if content() never answers TW_TILE_OWN. */
    int (*generate)(void *user, struct tw_cell cell, struct tw_tileset *ts);
    void *user;                         /* passed to content() and generate() */
    uint32_t max_cluster_triangles;     /* for generated tiles; 0: 2048 */
    /* Coarser levels of the provider's own, drawn far away (a baked
     * tileset's; README "Hierarchical cells"); 0: none. Level k, 1 <= k <=
     * levels <= TW_PROVIDER_MAX_LEVELS, holds blocks of 2^k x 2^k cells:
     * block (bi, bj) is the cells (bi 2^k + x, bj 2^k + z), 0 <= x, z <
     * 2^k, its tile block-local (the corner of cell (bi 2^k, bj 2^k) at the
     * origin, footprint 2^k W x 2^k D) and inside the common box stretched
     * over the block. level_error[k - 1] is the level's geometric error in
     * metres (how far a block's surfaces may lie from its cells'): a block
     * is drawn instead of its cells where that error projects to at most
     * the world's max_screen_error pixels, with levels of detail on.
     * generate_level() writes a block's tile as generate() writes a cell's:
     * the same threads, rules and return values. A world refuses more
     * levels, no generate_level() or an error that is not a finite
     * non-negative number (TW_ERR_INVALID); with moving objects, or in
     * host rendering, it leaves the levels unused. */
    uint32_t levels;
    float level_error[TW_PROVIDER_MAX_LEVELS];
    int (*generate_level)(void *user, uint32_t level, struct tw_cell block,
                          struct tw_tileset *ts);
};

/* For a provider's generate() that cannot make its tile: records why in
 * ts (printf's fmt, up to 255 bytes; the world puts it in its log line and
 * in the TW_TILE_REFUSED event) and returns err (a negative tw_error; any
 * other value becomes TW_ERR_INVALID), for
 *     return tw_tileset_fail(ts, TW_ERR_IO, "%s: %s", path, strerror(errno)); */
#if defined(__GNUC__)
__attribute__((format(printf, 3, 4)))
#endif
int tw_tileset_fail(struct tw_tileset *ts, int err, const char *fmt, ...);

/* Every heap byte a tileset holds (its arrays at their capacity, the mesh
 * data, the clusters): what it costs in memory, exactly. */
uint64_t tw_tileset_bytes(const struct tw_tileset *ts);

#ifdef __cplusplus
}
#endif

#endif
