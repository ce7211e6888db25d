/*
 * What the library's modules share of tiles/ beyond the public tiles.h:
 * formatted logging and escaping, box arithmetic, cell arithmetic, the
 * per-frame limits, packing a finished tileset, selection, the cell map and
 * the tile cache. Not installed; tools/ and tests/ reach it through the
 * module libraries.
 */
#ifndef TW_TILES_TILES_INTERNAL_H
#define TW_TILES_TILES_INTERNAL_H

#include <stdarg.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "tileworld/tiles.h"

/* ---- hashing ------------------------------------------------------------ */

/* FNV-1a: h for n more bytes at p; from TW_HASH_START. */
#define TW_HASH_START 0xcbf29ce484222325ull
uint64_t tw_hash_more(uint64_t h, const void *p, uint64_t n);
uint64_t tw_hash_bytes(const uint8_t *p, uint64_t n);

/* ---- logging ------------------------------------------------------------ */

/* Formats a message and hands it to the logger (no-op for a zeroed one). */
void tw_log_printf(const struct tw_log *log, enum tw_log_level level,
                   const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
void tw_log_vprintf(const struct tw_log *log, enum tw_log_level level,
                    const char *fmt, va_list ap);

/* Escapes text taken from an input file (a name, a key, a URI) so that a
 * message stays one line of plain text on a terminal: newline, carriage
 * return and tab become \n, \r and \t, other C0 controls, DEL and bytes that
 * are not valid UTF-8 become \xHH, the C1 controls and the bidirectional
 * overrides (U+202A..U+202E, U+2066..U+2069) become \uHHHH. Everything else
 * (printable ASCII, backslash included, and valid UTF-8) is kept, so that
 * escaping escaped text changes nothing. Writes at most size bytes into out
 * (NUL-terminated; "..." ends a cut) and returns out. tw_log_vprintf()
 * applies it to every message, so that a logger never sees a control
 * character; escaping the pieces where they are quoted as well keeps a
 * message's own quotes meaningful. */
const char *tw_log_escape(const char *text, char *out, size_t size);
/* The same for n bytes that may hold NUL bytes (shown as \x00). */
const char *tw_log_escape_bytes(const void *data, size_t n, char *out, size_t size);
/* tw_log_escape(), and every backslash doubled (\\), so that the text can be
 * told from the escapes in it: for quoting text such as a program's
 * arguments, which may hold backslashes of their own. Escaping twice
 * doubles the backslashes again. */
const char *tw_log_escape_reversible(const char *text, char *out, size_t size);

/* ---- boxes -------------------------------------------------------------- */

struct tw_box tw_box_empty(void);
bool tw_box_is_empty(const struct tw_box *b);
void tw_box_add_point(struct tw_box *b, const float p[3]);
void tw_box_add_box(struct tw_box *b, const struct tw_box *o);
/* Box of the eight corners of b under the affine 3x4 row-major transform m. */
struct tw_box tw_box_transform(const struct tw_box *b, const float m[12]);
float tw_box_surface_area(const struct tw_box *b);
/* Squared distance from p to the nearest point of b (0 inside). */
static inline float tw_box_distance2(const struct tw_box *b, const float p[3])
{
    float d2 = 0.0f;
    for (int k = 0; k < 3; k++) {
        float e = 0.0f;
        if (p[k] < b->min[k]) e = b->min[k] - p[k];
        else if (p[k] > b->max[k]) e = p[k] - b->max[k];
        d2 += e * e;
    }
    return d2;
}

/* ---- cells --------------------------------------------------------------- */

/* Floor division and the matching non-negative modulo, exact for all
 * int64_t a and b > 0. */
int64_t tw_tiles_floor_div(int64_t a, int64_t b);
int64_t tw_tiles_floor_mod(int64_t a, int64_t b);

/* The same for a local offset in double (as read from a file): the cells
 * are split off in double, so that a large offset keeps its precision, and
 * the remainder is rounded to float. Returns TW_ERR_INVALID (out unchanged)
 * if an offset or the footprint is not finite, or the cell would overflow. */
int tw_tiles_normalize_double(struct tw_cell cell, const double local[3], float w, float d,
                              struct tw_world_pos *out);

/* The position of cell's origin relative to origin's origin, in metres:
 * ((cell.i - origin.i) * w, 0, (cell.j - origin.j) * d). The difference is
 * taken in int64_t, scaled in double and only then rounded to float, so it is
 * exact-ish for nearby cells wherever they lie. */
void tw_tiles_cell_offset(struct tw_cell cell, struct tw_cell origin, float w,
                          float d, float out[3]);

/* ---- limits -------------------------------------------------------------- */

/* The most cells one frame may consider (the cell scan of cull/ checks at
 * most this many, and reports when it had to stop): 256 x 256 cells. */
#define TW_TILES_MAX_CELLS_IN_VIEW 65536u
/* The view distance a tileset is checked against when it is loaded (the
 * runtime's default), metres. */
#define TW_TILES_REFERENCE_VIEW_DISTANCE 600.0f

/* An upper bound on the cells a frame with view distance view_distance
 * must consider on a grid of footprint w x d whose common box is
 * common_box: (2 R + box extent) / footprint + 2 cells along each axis,
 * multiplied, in double (never overflows: +inf for a zero footprint). A
 * tileset, or a view distance, whose bound exceeds TW_TILES_MAX_CELLS_IN_VIEW
 * costs more per frame than the runtime allows. */
double tw_tiles_cells_in_reach(const struct tw_box *common_box, float w, float d,
                               float view_distance);

/* Bakes instances list[0 .. count) of prototype p into tile-local arrays
 * the caller sized for their meshes' vertices and triangles: positions,
 * normals (the transform's linear part applied, not renormalised), colours
 * (the mesh's vertex colour, white where it has none, times the
 * instance's material) and indices (each mesh's after the last); their
 * numbers into *vertices and *triangles. What merging small instances and
 * levels of detail both start from. */
void tw_tileset_bake(const struct tw_tileset *ts, uint32_t p, const uint32_t *list, uint32_t count,
                     float *pos, float *nrm, uint8_t *rgba, uint32_t *idx, uint32_t *vertices,
                     uint32_t *triangles);

/* ---- levels of detail (DESIGN §17) ---------------------------------------- */

/* The most levels a content has besides its full detail (a prototype's,
 * a proxy's): with targets sqrt(2) apart, enough for city's prototypes to
 * end at their box (at 8, four of twelve stopped at 20 to 114 triangles,
 * and a block of 32x32 such cells was too heavy for a proxy). The stream's
 * instance keys hold a level in 4 bits. (This header is hashed into the
 * levels store's key with lod.c.) */
#define TW_LOD_MAX_LEVELS 12u
/* A level is kept only if it has at most this share of the previous one's
 * triangles: a level that saves little costs memory and a BVH for nothing. */
#define TW_LOD_KEEP_RATIO 0.6

/* The coarser levels of a finished tileset's prototypes, built by
 * meshoptimizer (lod.c): each prototype baked into one tile-local mesh
 * (colours baked into its vertices), welded by position and colour, its
 * triangles sorted by colour into classes, each class simplified on its
 * own for targets of error sqrt(2) apart; each corner given back the
 * normal of a full-detail vertex; each level's indices ordered for the
 * vertex cache and for overdraw; at most TW_LOD_MAX_LEVELS, the last possibly the
 * prototype's box. Level k of prototype p (k = 1 .. count[p]) is
 * levels->prototypes[first[p] + k - 1], with geometric error
 * error[first[p] + k - 1] in metres, measured both ways and by colour: the
 * largest distance from a full-detail vertex to the level's triangles of
 * its colour (at most its colour patch's size), and from the level's
 * triangles to the full detail's of theirs; it never decreases with k.
 * Every level lies within its prototype's box. */
struct tw_lods {
    struct tw_tileset *levels;  /* finished and packed; NULL: no prototype has a level */
    uint32_t source_count;      /* the source tileset's prototypes */
    uint32_t *first;            /* per source prototype */
    uint32_t *count;            /* per source prototype: its levels, 0 .. TW_LOD_MAX_LEVELS */
    float *error;               /* per level */
    uint32_t stored;            /* prototypes whose levels were read from the store */
};

/* The levels' store: an on-disk cache of what tw_lods_build() makes of a
 * prototype, keyed by the prototype's content (its baked geometry and box),
 * by lod.c's and this header's source text and by meshoptimizer's version, so that a second
 * process, or a tile made again, reads its levels back in milliseconds
 * instead of building them in seconds; read back, they are the same levels,
 * byte for byte (README "Levels of detail"). The store of folder dir
 * (made if missing, its parents too: tw_file_cache_open()), its files together at most max_bytes
 * (0: TW_LODS_STORE_BYTES), opened once per folder and kept until the
 * process ends (a worker left behind may still use it; the first opener's
 * max_bytes holds). TW_ERR_IO with a sentence in err where the folder
 * cannot be made. */
#define TW_LODS_STORE_BYTES (1ull << 30)
struct tw_file_cache;
int tw_lods_store(const char *dir, uint64_t max_bytes, struct tw_file_cache **out, char *err,
                  size_t err_size);

/* Builds the levels of ts (finished), their clusters of at most
 * max_cluster_triangles. Zeroes *out first; on an error (memory, or ts
 * unfinished) nothing is left to free. A level the tileset builder refuses
 * (out of reach, or no triangle with area once finished) ends its
 * prototype's levels, or leaves the tileset without levels: not an error.
 * Where stop (may be NULL) is set, it gives up soon after, with
 * TW_ERR_STATE (a tile's worker at the world's destroy: seconds of work
 * nobody will use). With a store (may be NULL; tw_lods_store()), each
 * prototype's levels are read from it where it holds them, and written to
 * it where they are built; a store that cannot be read or written only
 * costs the build. */
int tw_lods_build(const struct tw_tileset *ts, uint32_t max_cluster_triangles,
                  struct tw_file_cache *store, const atomic_bool *stop, struct tw_lods *out);
/* The levels of ts (finished) as tw_lods_build(ts, ts->max_cluster_triangles,
 * store, NULL, ...) makes them, built by the first call (its store) and kept with ts until
 * tw_tileset_destroy(): the worlds over one tileset share one build (a
 * city's takes seconds). Safe to call from several threads at once; the
 * result is read-only. A failed build is not kept: the next call tries
 * again. */
int tw_lods_of_tileset(const struct tw_tileset *ts, struct tw_file_cache *store,
                       const struct tw_lods **out);
struct tw_lods_cache;
/* For tileset.c: where ts keeps its levels, and how they go. */
struct tw_lods_cache **tw_tileset_lods_slot(const struct tw_tileset *ts);
void tw_lods_cache_free(struct tw_lods_cache *c);
/* Accepts a zeroed struct. */
void tw_lods_free(struct tw_lods *l);
/* Heap bytes held. */
uint64_t tw_lods_bytes(const struct tw_lods *l);
/* The coarsest level of source prototype p whose error is at most
 * max_error metres: 0 (full detail) when none is, or max_error <= 0. */
uint32_t tw_lods_pick(const struct tw_lods *l, uint32_t p, float max_error);

/* ---- tilesets ------------------------------------------------------------ */

/* Moves a finished tileset, its struct and every array it owns, into one
 * allocation, and replaces *ts with it (the old pointer is freed; pointers
 * into the old arrays are invalid). A tileset that lives long among
 * short-lived allocations (a streamed tile) otherwise leaves its dozens of
 * small arrays scattered over the heap, and the holes between them, when it
 * is freed, are pages the allocator cannot return; one block is returned
 * whole. tw_tileset_destroy() frees it as before; tw_tileset_bytes() is then
 * the block's size. TW_ERR_INVALID on an unfinished tileset; on
 * TW_ERR_NOMEM *ts is unchanged and still valid. */
int tw_tileset_pack(struct tw_tileset **ts);
/* What tw_tileset_fail() recorded in ts, or NULL. */
const char *tw_tileset_failure(const struct tw_tileset *ts);

/* Bytes of a vertex in the renderer's buffers: its position in floats (12),
 * its normal in 10-bit integers (4), its RGBA colour in bytes (4). */
#define TW_TILESET_GPU_VERTEX_BYTES 20u

/* Sum of all mesh data bytes, merged meshes included, at
 * TW_TILESET_GPU_VERTEX_BYTES a vertex and 12 a triangle: what the renderer
 * uploads once. */
uint64_t tw_tileset_geometry_bytes(const struct tw_tileset *ts);

/* The prototype shown at cell: a seeded hash of the (periodic) cell, mapped
 * through the prototypes' weights, or the host callback's answer as it is
 * (which may be out of range: a world takes that for an error). ts must be
 * finished. */
uint32_t tw_tiles_select(const struct tw_tileset *ts,
                         const struct tw_selection *sel, struct tw_cell cell);

/* ---- a hash map from cells to 64-bit values -------------------------------------- */

/* Open addressing with linear probing; grows, never shrinks (its size follows
 * the peak number of cells held, not how far the camera travelled). */
struct tw_cell_map;

int tw_cell_map_create(struct tw_cell_map **out);
void tw_cell_map_destroy(struct tw_cell_map *m);
/* The value stored for cell, or NULL. The pointer is valid until the next
 * insert or remove. */
uint64_t *tw_cell_map_find(const struct tw_cell_map *m, struct tw_cell cell);
/* Inserts or overwrites. */
int tw_cell_map_set(struct tw_cell_map *m, struct tw_cell cell, uint64_t value);
/* Removes cell; returns whether it was there. */
bool tw_cell_map_remove(struct tw_cell_map *m, struct tw_cell cell);
void tw_cell_map_clear(struct tw_cell_map *m);
size_t tw_cell_map_count(const struct tw_cell_map *m);
/* Heap bytes held. */
size_t tw_cell_map_bytes(const struct tw_cell_map *m);
/* Calls fn for every entry; fn returns true to remove the entry. */
void tw_cell_map_filter(struct tw_cell_map *m,
                        bool (*fn)(void *user, struct tw_cell cell, uint64_t value),
                        void *user);

/* ---- the tile cache (DESIGN §1, tile instances) --------------------------------- */

/* Names a tile instance across frames. Eviction frees the instance and
 * bumps its slot's generation, so a kept handle reads as stale, never as
 * another tile. The zero handle is never valid. */
struct tw_tile_handle {
    uint32_t slot;
    uint32_t generation;
};

/* What the cache knows of an instance. */
struct tw_tile_info {
    struct tw_cell cell;
    uint32_t prototype;
    uint64_t created_frame;
    uint64_t visible_frame;   /* last frame it was found visible */
    size_t state_bytes;
};

/* Tile instances: created the first time a cell is found visible, kept while
 * it keeps being visible, evicted once it has not been visible for more than
 * evict_after frames. An instance owns a zeroed block of per-view state
 * (its culling state, e.g. CHC++ per-node visibility), never geometry. */
struct tw_tile_cache;

int tw_tile_cache_create(uint32_t evict_after, struct tw_tile_cache **out);
/* Frees every instance; accepts NULL. */
void tw_tile_cache_destroy(struct tw_tile_cache *c);

/* Finds the instance at cell; false if there is none. */
bool tw_tile_cache_find(const struct tw_tile_cache *c, struct tw_cell cell,
                        struct tw_tile_handle *out);
/* Finds the instance at cell or creates it with state_bytes zeroed bytes of
 * state, and marks it visible at frame. *created tells which happened. An
 * instance made for other content (another prototype, another state size)
 * is dropped and made afresh (*created is true; its old handles go stale). */
int tw_tile_cache_acquire(struct tw_tile_cache *c, struct tw_cell cell, uint32_t prototype,
                          size_t state_bytes, uint64_t frame, struct tw_tile_handle *out,
                          bool *created);
/* The instance's state block, or NULL if the handle is stale. Valid until
 * the instance is evicted. */
void *tw_tile_cache_state(const struct tw_tile_cache *c, struct tw_tile_handle h);
/* The instance's description, or NULL if the handle is stale. */
const struct tw_tile_info *tw_tile_cache_info(const struct tw_tile_cache *c,
                                              struct tw_tile_handle h);
bool tw_tile_cache_alive(const struct tw_tile_cache *c, struct tw_tile_handle h);
/* Packs a handle into 64 bits and back (e.g. as a CHC++ tile tag). */
uint64_t tw_tile_handle_pack(struct tw_tile_handle h);
struct tw_tile_handle tw_tile_handle_unpack(uint64_t packed);

/* Evicts every instance not visible since frame - evict_after; returns how
 * many went. */
uint32_t tw_tile_cache_evict(struct tw_tile_cache *c, uint64_t frame);
/* Evicts the instance at cell, if there is one; returns whether there was. */
bool tw_tile_cache_remove(struct tw_tile_cache *c, struct tw_cell cell);
/* Evicts every instance of a cell in [lo, hi] (inclusive); returns how many. */
uint32_t tw_tile_cache_remove_rect(struct tw_tile_cache *c, struct tw_cell lo, struct tw_cell hi);
/* Evicts the instance least recently visible before frame (a byte budget's
 * choice), adding its state bytes to *bytes (may be NULL); returns false
 * when every instance was visible at frame or later. */
bool tw_tile_cache_evict_oldest(struct tw_tile_cache *c, uint64_t frame, uint64_t *bytes);
uint32_t tw_tile_cache_count(const struct tw_tile_cache *c);
/* Exact heap bytes held by the cache: its tables and every state block. */
uint64_t tw_tile_cache_bytes(const struct tw_tile_cache *c);

/* True if a GL_RENDERER string names a CPU rasteriser (llvmpipe,
 * softpipe, swrast, SwiftShader): its "GPU" work is CPU time. */
static inline bool tw_renderer_name_is_software(const char *renderer)
{
    static const char *const names[] = {"llvmpipe", "softpipe", "swrast", "SwiftShader",
                                        "Software Rasterizer"};
    for (size_t k = 0; renderer && k < sizeof(names) / sizeof(names[0]); k++)
        if (strstr(renderer, names[k]))
            return true;
    return false;
}

/* ---- hierarchical levels of detail (blocks of cells) ---- */

/* A cell of a block that shows nothing. */
#define TW_HLOD_EMPTY UINT32_MAX

/* Builds the proxy of a block of side x side cells of the finished tileset
 * ts (side >= 1): one content that stands for the whole block, for the
 * runtime to simplify further with tw_lods_build(). Cell (x, z) of the
 * block, x and z in [0, side), shows prototype protos[z * side + x] of ts
 * (TW_HLOD_EMPTY: nothing) at its coarsest level of lods (built from ts; may
 * be NULL or have no levels: full detail) whose error is at most
 * max_input_error metres (tw_lods_pick), placed at (x * W, 0, z * D) where
 * W, D is ts's footprint. *out gets a finished, packed tileset of footprint
 * (side * W, side * D) with exactly one prototype: every instance of every
 * chosen level or prototype, its transform translated to its cell, its
 * material's colour kept; meshes and materials copied once each however
 * many cells use them; small instances merged as ts's merge_triangles says;
 * clusters of at most max_cluster_triangles. *input_error gets the largest
 * error of the levels used (0 if all are full detail). A block with no
 * triangles (all empty) gives TW_OK with *out = NULL. Deterministic: the
 * same inputs give the same meshes, instances and clusters, byte for byte.
 * TW_ERR_INVALID for side 0, a NULL argument, an unfinished ts, lods not of
 * ts, a prototype out of range; TW_ERR_LIMIT when the block's vertices or
 * triangles would not fit 32 bits, or it lies out of reach
 * (TW_TILES_MAX_COORD); TW_ERR_NOMEM. On an error *out is NULL and nothing
 * is left to free. The caller owns *out (tw_tileset_destroy()). Thread-safe
 * for distinct outputs: reads ts and lods only. */
int tw_hlod_block_build(const struct tw_tileset *ts, const struct tw_lods *lods,
                        const uint32_t *protos, uint32_t side, float max_input_error,
                        uint32_t max_cluster_triangles, struct tw_tileset **out,
                        float *input_error);

/* The coarser levels of a block's proxy (what tw_hlod_block_build() makes
 * of the same cells at base_error), made from its cells' own coarser
 * levels rather than by simplifying the proxy: level k is every cell at
 * its coarsest level within an error sqrt(2)^j times base_error (j = 1,
 * 2, ... up to the largest error of any cell's levels), merged as
 * tw_hlod_block_build() merges them, kept where it has at most
 * TW_LOD_KEEP_RATIO of the triangles of the level before (the proxy
 * itself first); at most TW_LOD_MAX_LEVELS. A proxy simplified within
 * what is left of the error above base_error kept what its cells kept at
 * base_error (tree crowns, a city's blocks clustered into patches larger
 * than it), while the same cells drawn alone went on to their coarser
 * levels. out: one source prototype (first[0] = 0, count[0] levels), each
 * level's error the largest of its cells' levels' errors less base_error
 * (never decreasing), what the runtime's selection adds to the proxy's
 * own (tw_world_hlod_get()). No levels (out zeroed, TW_OK) where lods has
 * none or no cell goes coarser. stop (may be NULL): set, the build gives
 * up with TW_ERR_STATE. Same errors as tw_hlod_block_build(); on an error
 * out is zeroed. The caller frees out (tw_lods_free()). Thread-safe for
 * distinct outputs. */
int tw_hlod_block_levels(const struct tw_tileset *ts, const struct tw_lods *lods,
                         const uint32_t *protos, uint32_t side, float base_error,
                         uint32_t max_cluster_triangles, const atomic_bool *stop,
                         struct tw_lods *out);

/* The most triangles a block's proxy is made of (before it is simplified)
 * for its level to pay: above, the proxy copies what the cells draw from
 * shared prototypes, for little. */
#define TW_HLOD_MAX_INPUT 65536u

/* A block is drawn as one proxy where it projects to at most this many
 * pixels across (the default of the world's tuning). */
#define TW_HLOD_BLOCK_PX 16.0f

/* The error, in metres, that the proxy of a block of 2^level x 2^level
 * cells of footprint w x d may have: max_screen_error pixels where the
 * block projects to block_px pixels across (2^level max(w, d)
 * max_screen_error / block_px). It is used from max_screen_error pixels
 * of that error on: the error times the focal length in pixels over
 * max_screen_error. */
float tw_hlod_level_error(const float footprint[2], uint32_t level, float max_screen_error,
                          float block_px);

/* What a block of 2^level x 2^level cells of ts, each at its coarsest
 * level of lods (may be NULL) within error metres, can hold at most: 4^level
 * cells of the heaviest prototype so drawn, in *input_triangles. Returns
 * whether that is within TW_HLOD_MAX_INPUT. */
bool tw_hlod_level_pays(const struct tw_tileset *ts, const struct tw_lods *lods, uint32_t level,
                        float error, uint64_t *input_triangles);

/* What tw_hlod_block_build() puts in its block, added instead to block: an
 * unfinished tileset of footprint (side * W, side * D) with no prototype
 * yet, which gets one prototype (no instances where every cell is empty)
 * and ts's merge_triangles; the caller finishes it. For a tile whose
 * tileset is made by someone else (a stream's worker). Same errors; on an
 * error block may hold part of the content (the caller destroys it). */
int tw_hlod_block_fill(const struct tw_tileset *ts, const struct tw_lods *lods,
                       const uint32_t *protos, uint32_t side, float max_input_error,
                       struct tw_tileset *block, float *input_error);

#endif
