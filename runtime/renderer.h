/*
 * The renderer: tilesets' meshes uploaded into GL buffers (gpu-store.c),
 * the GL implementation of struct tw_query_backend that draws clusters
 * per instance transform and queries boxes (query-backend.c, DESIGN §5),
 * the oracle's object-ID pass (id-pass.c), the offscreen framebuffer and
 * the host's GL state (renderer.c). Private to runtime/.
 */
#ifndef TW_RUNTIME_RENDERER_H
#define TW_RUNTIME_RENDERER_H

#include "cull/cull.h"
#include "runtime/gl.h"
#include "tileworld/runtime.h"

/* Counters the renderer keeps for the current frame. */
struct tw_render_counters {
    uint64_t triangles;
    uint32_t clusters;
    uint32_t draws;
    uint32_t queries;
    uint32_t query_boxes; /* boxes drawn by those queries */
    uint32_t blocking_reads;  /* waits whose result was not ready yet */
    double ms_wait;       /* blocked in wait() */
    double ms_backend;    /* inside draw()/issue()/wait() in all */
    uint32_t query_failures;  /* queries that could not be made (read as visible) */
    uint32_t waits;       /* calls of wait(): query results read, ready or not */
    uint32_t flushes;     /* calls of flush() */
    uint64_t bytes_read_back; /* bytes the CPU read back from the GPU (depth, buffers);
                                 query results are not counted */
};

struct tw_renderer;

/* Whether the backend offers the GPU HZB (cull.h's gpu_hzb_* operations):
 * on asks for it, and it is given where it was made (GL 4.3). Returns
 * whether it is now on. Off by default. */
bool tw_renderer_use_gpu_hzb(struct tw_renderer *r, bool on);
/* True if GL_RENDERER names a software rasteriser. */
bool tw_renderer_software(const struct tw_renderer *r);

/* log is borrowed for the renderer's lifetime. The GL context must be
 * current. */
int tw_renderer_create(uint32_t width, uint32_t height, tw_gl_get_proc_fn get_proc,
                       const struct tw_log *log, struct tw_renderer **out);

/* Uploads the meshes of a finished tileset into GL buffers of their own: its
 * prototypes become contents *first_content + p (what the backend draws, a
 * struct tw_cull_tile's content), each remembered with bvhs[p] (bvhs may be
 * NULL); *bytes (may be NULL) receives the buffers' size. ts and the BVHs
 * are borrowed until tw_renderer_release(). Between enter and leave. */
int tw_renderer_upload(struct tw_renderer *r, const struct tw_tileset *ts,
                       const struct tw_bvh *const *bvhs, uint32_t *first_content, uint64_t *bytes);
/* The tileset a live content is a prototype of, or NULL. */
const struct tw_tileset *tw_renderer_content_tileset(const struct tw_renderer *r, uint32_t content);
/* Says that contents first .. first + count - 1 are levels 1 .. count of
 * content base (DESIGN §17), for what a host is told it drew. */
void tw_renderer_tag_levels(struct tw_renderer *r, uint32_t base, uint32_t first, uint32_t count);
/* The full-detail content that content is a level of, and which (0: it
 * is one itself). */
uint32_t tw_renderer_content_base(const struct tw_renderer *r, uint32_t content, uint32_t *level);
/* The content of base's level level (0: base), or UINT32_MAX if it has none. */
uint32_t tw_renderer_level_content(const struct tw_renderer *r, uint32_t base, uint32_t level);
/* Frees the buffers of the tileset whose first content is first_content;
 * its contents' ids may be reused. Between enter and leave. */
void tw_renderer_release(struct tw_renderer *r, uint32_t first_content);
/* The prototype a content draws (and its BVH into *bvh, may be NULL), or
 * NULL for a content that is not live. */
const struct tw_prototype *tw_renderer_content(const struct tw_renderer *r, uint32_t content,
                                               const struct tw_bvh **bvh);
void tw_renderer_destroy(struct tw_renderer *r);

/* Moving objects: a content drawing proto (borrowed; its meshes and
 * materials are those of like's tileset, whose buffers it draws with) and
 * bvh, until removed. No GL. */
int tw_renderer_add_content(struct tw_renderer *r, uint32_t like, const struct tw_prototype *proto,
                            const struct tw_bvh *bvh, uint32_t *out);
/* A content joining two: proto's clusters below split are first's (the
 * same index), the others second's (less split); bvh is over proto's. What
 * it draws goes to its parts; what is recorded names it. No GL. */
int tw_renderer_add_composite(struct tw_renderer *r, uint32_t first, uint32_t second,
                              uint32_t split, const struct tw_prototype *proto,
                              const struct tw_bvh *bvh, uint32_t *out);
/* An added content's BVH, built afresh over the same prototype. */
void tw_renderer_set_content_bvh(struct tw_renderer *r, uint32_t content,
                                 const struct tw_bvh *bvh);
/* Drops an added content or composite; its id may be reused. */
void tw_renderer_remove_content(struct tw_renderer *r, uint32_t content);
/* A composite's clusters as runs of one part each, in order: fn is called
 * per run with the part's content, the part's cluster indices, and the
 * run's first index in clusters. Returns false (fn not called) for a
 * content that is not a composite. */
typedef void (*tw_renderer_run_fn)(struct tw_renderer *r, void *user, uint32_t part,
                                   const uint32_t *clusters, uint32_t count, uint32_t at);
bool tw_renderer_split(struct tw_renderer *r, uint32_t content, const uint32_t *clusters,
                       uint32_t count, tw_renderer_run_fn fn, void *user);

/* The renderer's GL entry points, for the world's other GL objects (its
 * timers); valid until it is destroyed. */
const struct tw_gl *tw_renderer_gl(const struct tw_renderer *r);
/* True when the renderer's GL context is the one current on the calling
 * thread (its objects can be used): false with no context current, or
 * another that does not share its objects. A shared context of the same
 * share group is told apart only while the host has no vertex array of the
 * same name in it. A few GL calls; no wait. */
bool tw_renderer_current(const struct tw_renderer *r);
/* The depth of the last frame into framebuffer target's depth attachment
 * (same size from the corner, same format): TW_ERR_GL when the GL refuses
 * it (another format), the error consumed. Between enter and leave. */
int tw_renderer_blit_depth(struct tw_renderer *r, uint32_t target);
/* GL_DEPTH_COMPONENT32F or GL_DEPTH_COMPONENT24. */
uint32_t tw_renderer_depth_format(const struct tw_renderer *r);

/* Host rendering: draw() instead of the renderer's own draws, into the
 * framebuffer bound when a frame begins (the host's), whose depth the
 * queries then test; cleared at the frame's start only with clear. The
 * backend then has no conditional rendering, no depth read-back and no GPU
 * HZB. After each draw() the renderer sets its own state again: the
 * framebuffer, viewport, depth test and function, and what enter turned
 * off (blending, scissor, stencil, ...). */
struct tw_renderer_host {
    void (*draw)(void *user, struct tw_cell cell, uint32_t content, const float offset[3],
                 const uint32_t *clusters, uint32_t count);
    void *user;
    bool clear;
    bool no_copies;     /* the host holds the tiles: uploads from now on make no GPU
                           buffers (their contents are drawn by the host only) */
};
void tw_renderer_set_host(struct tw_renderer *r, const struct tw_renderer_host *host);
bool tw_renderer_host_mode(const struct tw_renderer *r);
/* What the host made for content (its base's), kept for its draws. */
void tw_renderer_set_host_data(struct tw_renderer *r, uint32_t content, void *data);
void *tw_renderer_host_data(const struct tw_renderer *r, uint32_t content);
/* After a host's callback that may have changed GL state (between enter
 * and leave). */
void tw_renderer_after_host(struct tw_renderer *r);

/* Every call below that draws or reads runs between enter and leave: enter
 * saves the host's GL state (the first of nested calls) and sets what the
 * renderer relies on; leave restores it (the last). */
void tw_renderer_enter(struct tw_renderer *r);
void tw_renderer_leave(struct tw_renderer *r);

/* Binds the framebuffer, clears it and sets the view for the frame; resets
 * the counters. view_distance drives the fog. */
void tw_renderer_begin_frame(struct tw_renderer *r, const struct tw_view *v);
/* Ends the frame: sends its work to the GPU (glFlush), without waiting. */
void tw_renderer_end_frame(struct tw_renderer *r);
/* Waits for the GPU to finish everything sent (glFinish). */
void tw_renderer_finish(struct tw_renderer *r);
/* Clears the depth buffer to the near plane (occluded true: every fragment
 * drawn after fails the depth test, as a hidden cluster's do) or to the far
 * plane (false: as tw_renderer_begin_frame leaves it). The calibration's. */
void tw_renderer_clear_depth(struct tw_renderer *r, bool occluded);

/* The query backend drawing into this renderer. */
struct tw_query_backend tw_renderer_backend(struct tw_renderer *r);

const struct tw_render_counters *tw_renderer_counters(const struct tw_renderer *r);

/* Recording of drawn clusters (reset by tw_renderer_begin_frame). */
void tw_renderer_record_draws(struct tw_renderer *r, bool on);
const struct tw_drawn_cluster *tw_renderer_drawn(const struct tw_renderer *r, size_t *count);

/* The oracle's object-ID pass (DESIGN §8), into its own R32UI buffer and
 * depth buffer: begin clears it to TW_RENDERER_NO_ID; draw renders clusters
 * with ids first_id, first_id + 1, ... through the normal pass's vertex
 * shader and depth state; read copies width * height ids and (depth not
 * NULL) window depths, bottom row first. Not counted in the frame's
 * counters. */
#define TW_RENDERER_NO_ID UINT32_MAX
void tw_renderer_id_begin(struct tw_renderer *r, const struct tw_view *v);
void tw_renderer_id_draw(struct tw_renderer *r, uint32_t content, const float offset[3],
                         const uint32_t *clusters, uint32_t count, uint32_t first_id);
void tw_renderer_id_read(struct tw_renderer *r, uint32_t *ids, float *depth);
/* Reads the frame's window depth, width * height floats, bottom row first
 * (reversed float depth: near 1, far 0; else standard, near 0). */
void tw_renderer_read_depth(struct tw_renderer *r, float *depth);

/* Reads the colour buffer as RGB8, top row first. */
int tw_renderer_read_rgb(struct tw_renderer *r, uint8_t *rgb);

/* CPU time of the process, every thread, in milliseconds. */
double tw_renderer_cpu_ms(void);

/* ---- debugging and the viewer ------------------------------------------------------ */

/* True when depth is reversed float depth (glClipControl present); false:
 * standard 24-bit depth. */
bool tw_renderer_reversed_z(const struct tw_renderer *r);

/* One box of an occlusion query issued this frame, view-relative. */
struct tw_renderer_query_box {
    float min[3], max[3];
    uint32_t query;      /* its handle (boxes of a multiquery share it) */
    uint32_t boxes;      /* boxes in that query */
    bool tile;           /* a tile query (the common box), else a node query */
    int8_t result;       /* 1 visible, 0 hidden, -1 not read this frame */
};

/* On: the backend reports no query as ready before it is waited on, so
 * that what the methods do does not depend on the GPU's timing. */
void tw_renderer_set_deterministic(struct tw_renderer *r, bool on);

/* On: queries count the samples that pass (GL_SAMPLES_PASSED), for a
 * visibility threshold T > 0; off (the default): they only say whether any
 * passed (GL_ANY_SAMPLES_PASSED), which a GPU may answer sooner. */
void tw_renderer_set_count_samples(struct tw_renderer *r, bool on);
/* Testing only: every query box shrunk by shrink_fraction of its size. */
void tw_renderer_set_mutation(struct tw_renderer *r, float shrink_fraction);

/* Turns on or off the recording of query boxes (off by default; reset by
 * tw_renderer_begin_frame). The array belongs to the renderer and lives
 * until the next frame. */
void tw_renderer_record_queries(struct tw_renderer *r, bool on);
const struct tw_renderer_query_box *tw_renderer_queries(const struct tw_renderer *r, size_t *count);

/* A box that tw_world_draw_debug draws (debug.c): view-relative corners,
 * a straight RGBA colour. */
struct tw_renderer_debug_box {
    float min[3], max[3];
    float color[4];
};

/* Copies the colour image into GL framebuffer target (0: a window's),
 * scaled to width x height. */
void tw_renderer_blit(struct tw_renderer *r, uint32_t target, uint32_t width, uint32_t height);

#endif
