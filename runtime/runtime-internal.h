/*
 * What the tools and the tests reach of the runtime that a host does not:
 * the methods' parameters and the switches of measurements (DESIGN §6,
 * §7), the cost figures (DESIGN §14), frames of a fixed set, moving a path,
 * the debug views' names and colours.
 * Not installed; the programs in tools/ and the tests link the module
 * libraries, which hold these symbols (libtileworld.so does not export
 * them).
 */
#ifndef TW_RUNTIME_RUNTIME_INTERNAL_H
#define TW_RUNTIME_RUNTIME_INTERNAL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "bvh/bvh.h"
#include "cull/cull.h"
#include "tileworld/runtime.h"

/* What work costs on the GPU a world draws with (DESIGN §14), in
 * milliseconds of process CPU time (on a software rasteriser every thread's
 * work is CPU time; on a GPU it is what the CPU spends submitting and
 * waiting). Measured when a world is created, by timing queries of boxes
 * of known screen size and draws of clusters of known triangle counts, each
 * batch closed by glFinish. */
struct tw_calibration {
    double query_ms;         /* one occlusion query of one box: issue, draw, read back */
    double query_batched_ms; /* the same query issued in a batch of them, all read at
                                its end (0: query_ms) */
    double query_box_ms;     /* each further box of a query (an instance more) */
    double query_pixel_ns;   /* each pixel its boxes cover, nanoseconds */
    double draw_ms;          /* one draw call (one cluster); the draw figures are of a
                                hidden cluster, every fragment failing the depth test */
    double triangle_ns;      /* each triangle drawn, nanoseconds */
    double draw_pixel_ns;    /* each pixel a drawn cluster's box covers, nanoseconds */
    double calibrate_ms;     /* CPU time the measurement took (0: not measured) */
    bool measured;           /* false: figures given in the settings, or the nominal
                                ones of a deterministic world */
};

/* A world's tuning. Zero-initialisable: tw_world_create_tuned() resolves
 * every zero field to its default (tw_world_default_tuning()). */
/* Where the HZB methods' depth pyramid is built and tested. */
enum tw_hzb_pyramid {
    TW_HZB_PYRAMID_AUTO = 0,    /* the GPU's on a GPU with compute shaders, the CPU's on a
                                   software rasteriser (there the CPU's C loop is cheaper
                                   than the rasteriser's compute) */
    TW_HZB_PYRAMID_GPU,         /* compute passes; the CPU's where GL 4.3 is missing */
    TW_HZB_PYRAMID_CPU,         /* depth read back every frame, built and tested on the CPU */
};

struct tw_world_tuning {
    struct tw_chc_settings chc;        /* chc.no_cost_model: CHC++ with unit query costs */
    struct tw_tilequery_settings tilequery;
    struct tw_bvh_settings bvh;
    struct tw_calibration calibration; /* zeroed (query_ms 0): measured at creation
                                          (a deterministic world: the nominal figures);
                                          else these figures */
    enum tw_hzb_pyramid hzb_pyramid;
    float mutate_query_shrink;         /* testing only: every query box shrunk by this
                                          fraction of its size, a deliberately broken
                                          culler that the accuracy checks must catch */
    uint32_t hlod_levels;              /* hierarchical cells (README "Hierarchical
                                          cells"): levels, cells included, up to
                                          TW_CULL_MAX_LEVELS; 0 or 1: none. Needs
                                          levels of detail and a tileset whose cells
                                          show shared prototypes */
    float hlod_block_px;               /* a block is drawn as one proxy where it
                                          projects to at most this many pixels across;
                                          default 16 */
};

/* Resolves the defaults of every zero field of t. */
void tw_world_default_tuning(struct tw_world_tuning *t);

/* tw_world_create() with a tuning (NULL: the defaults). */
int tw_world_create_tuned(const struct tw_world_settings *s, const struct tw_world_tuning *t,
                          struct tw_world **out);

/* The world's resolved tuning. */
const struct tw_world_tuning *tw_world_tuning(const struct tw_world *w);

/* The limits the methods are measured against, past the public methods:
 * frames that know their visibility from the verify pass's untimed
 * ID-buffer pass and draw only what it found (the oracle: the clusters with
 * a visible pixel; the box oracle: those visible or whose own box shows in
 * front of the frame's true depth, README "The box oracle"). Never a method
 * a renderer could use, so not in runtime.h; the tools measure them beside
 * the methods. */
#define TW_METHOD_ORACLE ((enum tw_method)TW_METHOD_COUNT)
#define TW_METHOD_BOX_ORACLE ((enum tw_method)(TW_METHOD_COUNT + 1))
#define TW_METHOD_ALL (TW_METHOD_COUNT + 2)   /* the methods and the limits */

/* tw_method_from_name() for the limits too ("oracle", "box-oracle"). */
int tw_method_or_limit_from_name(const char *name, enum tw_method *out);
/* tw_world_set_method() for the limits too. A world created with
 * tw_world_create_tuned() may have a limit as its settings' method. */
int tw_world_set_method_or_limit(struct tw_world *w, enum tw_method m);
/* The same for a viewport's camera. */
int tw_viewport_set_method_or_limit(struct tw_viewport *vp, enum tw_method m);

/* TW_METHOD_DEFAULT resolved; every other value as it is. */
enum tw_method tw_method_resolve(enum tw_method m);
/* True if method m under tuning t (NULL: the defaults) must never miss a
 * visible pixel: every method, unless its occlusion queries cull below a
 * visibility threshold T > 0 (contribution culling, DESIGN §7). */
bool tw_method_conservative(enum tw_method m, const struct tw_world_tuning *t);
/* True for the limits, oracle and box-oracle: they know the frame's
 * visibility from an untimed ID-buffer pass, so they are what the methods
 * are measured against, never a method a renderer could use. */
bool tw_method_limit(enum tw_method m);

/* The cost figures the world decides with (DESIGN §14): as calibrated
 * when it was created. Owned by the world; valid until it is destroyed. */
const struct tw_calibration *tw_world_calibration(const struct tw_world *w);

/* The BVH of prototype p (built when the world was created). */
const struct tw_bvh *tw_world_bvh(const struct tw_world *w, uint32_t p);


/* Renders one frame from cam that draws exactly clusters, with no culling
 * and no queries (a frozen culled set, looked at from elsewhere; or a
 * method's set drawn again, to tell what drawing it cost from what finding
 * it did: tileworld bench --split). The set is drawn tile by tile, as the
 * oracle draws its own: tiles in the order they first appear in it, each
 * tile's clusters in their order in it. Fills the drawing fields of *stats
 * (may be NULL), ms_frame and cpu_ms as tw_world_frame() does
 * (tw_world_finish() adds the GPU's end; the GPU-time fields read unknown:
 * no timers); leaves every method's temporal state and the cost model alone. clusters is only read during the call. */
int tw_world_frame_fixed(struct tw_world *w, const struct tw_camera *cam,
                         const struct tw_drawn_cluster *clusters, size_t count,
                         struct tw_frame_stats *stats);


/* A provider's tile for cell as a world makes it (runtime/workers.c):
 * generate() into a fresh tileset named "I,J", then the world's checks: a
 * positive return other than TW_GENERATE_EMPTY is refused, a failure
 * carries the provider's own reason (tw_tileset_fail), at most
 * max_triangles triangles (0: no cap), exactly one prototype, finished into
 * the provider's clusters, inside its bound. Returns TW_OK with *out (the
 * caller's to destroy), TW_GENERATE_EMPTY, or a negative error with the
 * cause in why; *out is NULL but on TW_OK. Thread-safe as generate() is:
 * the world's workers and `tileworld bake` make their tiles with it. */
int tw_provider_make_tile(const struct tw_tile_provider *p, struct tw_cell cell,
                          uint64_t max_triangles, struct tw_tileset **out, char *why,
                          size_t why_size);

/* Moves every key by (di, dj) cells; TW_ERR_INVALID on int64 overflow. */
int tw_path_translate(struct tw_path *p, int64_t di, int64_t dj);

/* Short name of a kind ("visible", "leaf", ...), and its colour (straight RGBA). */
const char *tw_debug_kind_name(enum tw_debug_kind kind);
void tw_debug_kind_color(enum tw_debug_kind kind, float rgba[4]);

#endif
