/*
 * The renderer's insides, shared by the files that make it: renderer.c
 * (creation, the frame, the framebuffer, the host's GL state),
 * gpu-store.c (uploaded tilesets), query-backend.c (the GL query
 * backend), id-pass.c (the oracle's object-ID pass) and debug.c (debug
 * drawing). Private to runtime/.
 */
#ifndef TW_RUNTIME_RENDERER_PRIVATE_H
#define TW_RUNTIME_RENDERER_PRIVATE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "runtime/gl.h"
#include "runtime/programs.h"
#include "runtime/renderer.h"

/* What the renderer has set up to draw with: nothing known, the scene
 * program and masks (query-backend.c's draw), or the query boxes'. */
enum tw_renderer_mode { TW_RENDERER_MODE_NONE, TW_RENDERER_MODE_DRAW, TW_RENDERER_MODE_QUERY };

/* One uploaded tileset: every mesh in one vertex and one index buffer. */
struct tw_gpu_buffers {
    const struct tw_tileset *ts;    /* borrowed until released */
    GLuint vao, vbo, ibo;
    uint32_t *base_vertex, *first_index;    /* per mesh */
    uint32_t first_content;         /* its prototypes' contents: first_content + p */
    uint64_t bytes;                 /* of the GL buffers */
    bool live;
};

/* What content c draws: prototype proto of buffers[buffers]. */
struct tw_gpu_content {
    uint32_t buffers;
    uint32_t proto;
    const struct tw_bvh *bvh;       /* the prototype's, borrowed */
    bool live;
};

struct tw_renderer {
    struct tw_gl gl;
    struct tw_log log;
    uint32_t width, height;
    /* Depth convention: reversed float depth (near = 1, far = 0) when
     * glClipControl is there, else standard 24-bit depth (near = 0). */
    bool reversed_z;
    bool has_clip_control;
    bool gl_loaded;        /* every entry point of the table is there */
    /* The host's GL state, saved while the library is inside a call. */
    struct tw_gl_state host_state;
    uint32_t entered;

    struct tw_programs programs;
    GLuint fbo, color_rb, depth_rb;
    /* The unit box: 8 corners, 36 face indices wound inwards, then 24 edge
     * indices (debug drawing); the query VAO shares its buffers. */
    GLuint box_vao, box_vbo, box_ibo;
    GLuint bound_vao;      /* the vertex array bound, 0 when not known */
    enum tw_renderer_mode mode;
    struct tw_render_counters counters;

    /* gpu-store.c: uploaded tilesets (a shared tileset, or one generated
     * tile each) and the contents they hold: content c draws prototype
     * contents[c].proto of buffers contents[c].buffers. Freed slots go on
     * free lists. */
    struct tw_gpu_buffers *buffers;
    uint32_t buffer_count, buffer_cap, *free_buffers, free_buffer_count;
    struct tw_gpu_content *contents;
    uint32_t content_count, content_cap, *free_contents, free_content_count;

    /* query-backend.c. Query boxes: one instanced draw per query, each box
     * an instance whose corners (view-relative, margin included) come from
     * a ring buffer, orphaned when it wraps. */
    GLuint query_vao, query_ring;
    uint32_t query_ring_next;          /* next free box of the ring */
    float *query_corners;              /* staging: min, max per box */
    uint32_t query_corner_cap;         /* boxes */
    /* Query objects: handle h (> 0) names queries[h - 1]; released handles
     * go on a free list and are reused. */
    GLuint *queries;
    uint32_t *free_queries;
    uint32_t query_count, free_count, query_cap;
    float eye[3];          /* the frame's, view-relative */
    /* The draw's scratch: clusters grouped by instance (one multi-draw
     * each), run_seen[i] == run_stamp marking instances met in this call. */
    uint32_t *run_next, *run_clusters, run_cap;
    GLsizei *run_counts;
    const void **run_offsets;
    GLint *run_bases;
    uint32_t *run_seen, *run_first, *run_last, *run_order, run_instance_cap, run_stamp;
    bool recording;        /* of drawn clusters */
    struct tw_drawn_cluster *drawn;
    size_t drawn_count, drawn_cap;
    /* Recording of query boxes for debugging: query_record[h - 1] is the
     * index + 1 of handle h's first record this frame (0: none). */
    bool recording_queries;
    struct tw_renderer_query_box *query_boxes;
    size_t query_box_count, query_box_cap;
    uint32_t *query_record;
    const struct tw_box *tile_query_box;   /* queries on this box are tile queries */
    bool deterministic;    /* no query is ready before it is waited on */
    GLenum query_target;   /* GL_ANY_SAMPLES_PASSED, or GL_SAMPLES_PASSED to count them */
    float mutate_shrink;   /* testing: query boxes shrunk by this fraction */

    /* id-pass.c: the object-ID buffer, one uint per pixel, its own depth. */
    GLuint id_fbo, id_rb, id_depth_rb;
};

/* renderer.c */
/* Logs why an offscreen framebuffer (what: its name) cannot be completed
 * and returns TW_ERR_NOMEM (the driver's memory) or TW_ERR_GL. */
int tw_renderer_framebuffer_failed(struct tw_renderer *r, const char *what);

/* gpu-store.c */
/* The buffers and prototype of a live content, with its vertex array bound. */
const struct tw_gpu_buffers *tw_renderer_bind_content(struct tw_renderer *r, uint32_t content,
                                                      const struct tw_prototype **proto);
/* Frees every uploaded tileset (GL buffers while gl_loaded, between enter
 * and leave) and the store's arrays. */
void tw_renderer_store_finish(struct tw_renderer *r);

/* query-backend.c */
/* Makes the query VAO and its ring buffer, on the unit box's buffers. */
void tw_renderer_queries_init(struct tw_renderer *r);
/* Starts the backend's frame at eye v->eye: counters, recorded draws and
 * recorded query boxes reset. */
void tw_renderer_queries_begin_frame(struct tw_renderer *r, const struct tw_view *v);
/* Deletes the query objects and the ring (while gl_loaded, between enter
 * and leave) and frees the backend's arrays. */
void tw_renderer_queries_finish(struct tw_renderer *r);

/* id-pass.c */
/* Makes the object-ID framebuffer, its depth in depth_format; leaves it
 * bound. TW_ERR_NOMEM or TW_ERR_GL (logged) when it cannot be completed. */
int tw_renderer_id_init(struct tw_renderer *r, GLenum depth_format);
/* Deletes it (while gl_loaded, between enter and leave). */
void tw_renderer_id_finish(struct tw_renderer *r);

#endif
