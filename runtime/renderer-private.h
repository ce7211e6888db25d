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
    /* Levels of detail (tw_renderer_tag_levels): the full-detail content
     * this one is a level of (itself: level 0), and for a full-detail
     * one, its levels' contents levels_first .. + levels_count - 1. */
    uint32_t base, level, levels_first, levels_count;
    void *host_data;                /* host rendering: what the host's prepare() made */
    /* Added contents (tw_renderer_add_content): a prototype of the host's,
     * not one of buffers' tileset, drawn with buffers' meshes. A composite
     * (tw_renderer_add_composite) draws own's clusters below split as
     * content part[0] and the others, less split, as part[1]; it is never
     * bound itself. */
    const struct tw_prototype *own;
    bool composite;
    uint32_t part[2], split;
};

/* What one indirect command draws with (draws.c): its instance's
 * transform (row-major 3x4, mesh-local -> tile-local), the tile's offset
 * (view-relative) with the ID pass's id in w, and the material's colour.
 * The vertex stage reads it as instanced attributes 3 to 7. */
struct tw_draw_record {
    float model[12];
    float offset[4];
    float color[4];
};

/* GL's DrawElementsIndirectCommand. */
struct tw_draw_command {
    uint32_t count;
    uint32_t instance_count;
    uint32_t first_index;
    int32_t base_vertex;
    uint32_t base_instance;     /* the record's index */
};

/* The HZB on the GPU (gpu-hzb.c). */
#define TW_GPU_HZB_SLOTS 8
struct tw_gpu_vec4 {
    float v[4];
};
/* A run of candidates' commands drawn from one tileset's buffers. */
struct tw_gpu_segment {
    uint32_t buffers, content;  /* the buffers, and a content of theirs to bind them by */
    uint32_t first, count;      /* commands */
};
/* One frame's answers in flight: read back under a fence. */
struct tw_gpu_hzb_slot {
    GLsync fence;
    bool pending;
    const void *owner;          /* whose frame (gpu_hzb_build's owner) */
    uint64_t frame;
    uint32_t count;             /* candidates */
    size_t bytes;               /* of its read-back buffer */
};
/* What a candidate draws, for the recording of drawn clusters. */
struct tw_gpu_hzb_where {
    struct tw_cell cell;
    uint32_t content;
    uint32_t first_cluster;     /* in cluster_ids */
};
/* The result buffer: the triangles and clusters the passing candidates
 * drew, then one bit per candidate. */
#define TW_GPU_HZB_RESULT_HEAD 2u
struct tw_gpu_hzb {
    bool live;                  /* compute shaders, and everything made */
    bool on;                    /* offered to the methods (tw_renderer_use_gpu_hzb) */
    GLuint reduce, test;        /* programs */
    GLint u_view_proj, u_proj, u_near, u_size, u_levels, u_reversed, u_built, u_count;
    GLint u_level_at, u_level_w;
    GLint u_src_size, u_dst_size, u_src_at, u_dst_at, u_reduce_reversed;
    GLuint buffers[4];          /* boxes, info, the pyramid, results */
    GLuint readback[TW_GPU_HZB_SLOTS];
    struct tw_gpu_hzb_slot slot[TW_GPU_HZB_SLOTS];
    /* The pyramid in buffers[2]: level k (at level_at[k] floats, level_w[k]
     * x level_h[k]) is the depth reduced k + 1 times, the farthest of each
     * 2 x 2. */
    uint32_t pyramid_w, pyramid_h, levels;
    GLint level_w[24], level_h[24], level_at[24];
    bool built;
    struct tw_view view;        /* the frame's */
    const void *owner;
    uint64_t frame;
    /* The frame's candidates, staged: boxes and info as the test reads them. */
    struct tw_gpu_vec4 *boxes;  /* two per candidate: min (w: always), max */
    uint32_t (*info)[4];        /* first command, commands, triangles, 0 */
    struct tw_gpu_hzb_where *where;
    size_t count, box_cap, info_cap, where_cap;
    struct tw_draw_command *commands;
    size_t command_count, command_cap;
    struct tw_draw_record *records;
    size_t record_count, record_cap;
    uint32_t *cluster_ids;
    size_t cluster_id_count, cluster_id_cap;
    struct tw_gpu_segment *segments;
    size_t segment_count, segment_cap;
    bool key_valid;             /* the tile placement whose records are mapped */
    struct tw_cell key_cell;
    uint32_t key_content, key_stamp;
    uint32_t *result;           /* the latest read: head, then bits */
    size_t result_cap;
    uint32_t result_count;
    uint64_t result_frame;
};

struct tw_renderer {
    struct tw_gl gl;
    struct tw_log log;
    uint32_t width, height;
    /* Depth convention: reversed float depth (near = 1, far = 0) when
     * glClipControl is there, else standard 24-bit depth (near = 0). */
    bool reversed_z;
    bool has_clip_control;
    bool software;         /* GL_RENDERER names a software rasteriser */
    bool has_compute;      /* GL 4.3 compute: the depth is a texture and the GPU HZB runs */
    bool gl_loaded;        /* every entry point of the table is there */
    /* The host's GL state, saved while the library is inside a call. */
    struct tw_gl_state host_state;
    uint32_t entered;

    struct tw_programs programs;
    GLuint fbo, color_rb, depth_rb;
    /* The unit box: 8 corners, 36 face indices wound inwards, then 24 edge
     * indices (debug drawing); the query VAO shares its buffers. */
    GLuint box_vao, box_vbo, box_ibo;
    /* A fence made at creation and kept: a sync object is known only to
     * its context's share group, so glIsSync() on it (with the box VAO,
     * which only its own context knows) tells whether the calling thread
     * has the world's context current (tw_renderer_current). */
    GLsync token;
    /* Host rendering (tw_renderer_set_host): the host draws the clusters
     * into its framebuffer, bound when the frame began, where the queries
     * go too; host.draw NULL: the renderer draws into its own. */
    struct tw_renderer_host host;
    GLuint host_fbo;       /* the host's draw framebuffer of this frame */
    bool in_frame;         /* between begin_frame and end_frame */
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
    /* Composites' draws, split into their parts' runs (gpu-store.c). */
    uint32_t *split_clusters;
    uint32_t split_cap;
    /* The draw's scratch: run_record[i] is instance i's record in this
     * call when run_seen[i] == run_stamp. */
    uint32_t *run_seen, *run_record, run_instance_cap, run_stamp;
    bool recording;        /* of drawn clusters */
    struct tw_drawn_cluster *drawn;
    size_t drawn_count, drawn_cap;
    /* Recording of query boxes for debugging: query_record[h - 1] is the
     * index + 1 of handle h's first record this frame (0: none). */
    bool recording_queries;
    struct tw_renderer_query_box *query_boxes;
    size_t query_box_count, query_box_cap;
    uint32_t *query_record;
    bool next_is_tile;     /* the next query issued is a tile query (debug views) */
    bool deterministic;    /* no query is ready before it is waited on */
    GLenum query_target;   /* GL_ANY_SAMPLES_PASSED, or GL_SAMPLES_PASSED to count them */
    float mutate_shrink;   /* testing: query boxes shrunk by this fraction */

    /* draws.c: records and commands staged by a draw, then streamed
     * into rings (orphaned when they wrap). */
    bool has_mdi;          /* glMultiDrawElementsIndirect with base instances (GL 4.3) */
    GLuint record_ring, command_ring;
    uint32_t record_ring_cap, record_ring_next, command_ring_cap;
    size_t command_ring_bytes;
    struct tw_draw_record *stage_records;
    struct tw_draw_command *stage_commands;
    size_t stage_record_cap, stage_command_cap;
    GLint host_indirect_buffer;    /* saved on enter, restored on leave */

    /* gpu-hzb.c; the image's depth is a texture where it is live. */
    struct tw_gpu_hzb ghzb;
    GLuint depth_texture;
    struct tw_gl_compute_state host_compute;   /* saved on enter, restored on leave */

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

/* query-backend.c */
/* Stages a draw of clusters of proto (buffers b) placed at offset into
 * r->stage_records and r->stage_commands: one command per cluster in the
 * order given, a record per instance (first_id == UINT32_MAX) or, for the
 * ID pass, per cluster with ids first_id, first_id + 1, ... Returns
 * false when out of memory; *records receives the records' number. */
bool tw_renderer_stage_clusters(struct tw_renderer *r, const struct tw_gpu_buffers *b,
                                    const struct tw_prototype *proto, const float offset[3],
                                    const uint32_t *clusters, uint32_t count, uint32_t first_id,
                                    uint32_t *records);

/* Enters the scene's drawing state (program, masks). */
void tw_renderer_enter_draw_mode(struct tw_renderer *r);
/* Room in the instance -> record map for a prototype of that many
 * instances; false: out of memory. */
bool tw_renderer_instance_map(struct tw_renderer *r, uint32_t instances);
/* Adds clusters to the recording of drawn clusters. */
void tw_renderer_record_clusters(struct tw_renderer *r, struct tw_cell cell, uint32_t prototype,
                                 const uint32_t *clusters, uint32_t count);

/* gpu-hzb.c */
/* Makes the compute programs and buffers; false (logged) where they
 * cannot be had: the HZB is then the CPU's. */
bool tw_renderer_gpu_hzb_init(struct tw_renderer *r);
void tw_renderer_gpu_hzb_finish(struct tw_renderer *r);
void tw_renderer_gpu_hzb_begin_frame(struct tw_renderer *r, const struct tw_view *v);
/* Fills be's gpu_hzb_* operations where the GPU HZB is live. */
void tw_renderer_gpu_hzb_ops(struct tw_renderer *r, struct tw_query_backend *be);

/* draws.c */
/* Makes the rings (the command ring only with mdi: GL 4.3). */
void tw_renderer_draws_init(struct tw_renderer *r, bool mdi);
void tw_renderer_draws_finish(struct tw_renderer *r);
/* Sets up the record attributes of the vertex array being made (bound). */
void tw_renderer_draws_vertex_array(struct tw_renderer *r);
/* Room for that many staged records and commands; false: out of memory. */
bool tw_renderer_draws_reserve(struct tw_renderer *r, uint32_t records, uint32_t commands);
/* Fills a record of instance in placed at offset, with colour color and
 * the ID pass's id (exact up to 2^24). */
void tw_renderer_draws_record(struct tw_draw_record *rec, const struct tw_instance *in,
                              const float offset[3], const float color[4], float id);
/* Fills a command drawing cluster cl of buffers b (tileset ts) with record. */
void tw_renderer_draws_command(struct tw_draw_command *c, const struct tw_gpu_buffers *b,
                               const struct tw_tileset *ts, const struct tw_cluster *cl,
                               uint32_t record);
/* Draws commands with the vertex array of their buffers bound: base
 * instances index records (rewritten into the ring's indices). One
 * multi-draw with GL 4.3, else one draw per command. Returns the GL draw
 * calls made. */
uint32_t tw_renderer_draws_submit(struct tw_renderer *r, const struct tw_draw_record *rec,
                              uint32_t records, struct tw_draw_command *cmd, uint32_t commands);
/* The rings themselves, for the GPU's own culling (gpu-hzb.c): records
 * streamed (their first index returned), commands streamed (their byte
 * offset in the command ring returned, 256-byte aligned), and a
 * multi-draw of n commands at byte offset at. */
uint32_t tw_renderer_draws_put_records(struct tw_renderer *r, const struct tw_draw_record *rec,
                                       uint32_t n);
size_t tw_renderer_draws_put_commands(struct tw_renderer *r, const struct tw_draw_command *cmd,
                                      uint32_t n);
void tw_renderer_draws_commands(struct tw_renderer *r, size_t at, uint32_t n);

/* id-pass.c */
/* Makes the object-ID framebuffer, its depth in depth_format; leaves it
 * bound. TW_ERR_NOMEM or TW_ERR_GL (logged) when it cannot be completed. */
int tw_renderer_id_init(struct tw_renderer *r, GLenum depth_format);
/* Deletes it (while gl_loaded, between enter and leave). */
void tw_renderer_id_finish(struct tw_renderer *r);

/* After a host's callback (draw, prepare, release): the state enter sets,
 * clip control and, in a frame, its framebuffer, viewport and depth test,
 * again (renderer.c). */
void tw_renderer_after_host(struct tw_renderer *r);

#endif
