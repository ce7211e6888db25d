/*
 * GPU time of frames (DESIGN §15): GL_TIMESTAMP queries marked at the
 * boundaries of a frame's passes, in a ring of entries, and read only once
 * GL says they are available: never waited on. Private to runtime/.
 */
#ifndef TW_RUNTIME_GPUTIME_H
#define TW_RUNTIME_GPUTIME_H

#include "runtime/gl.h"
#include "runtime/runtime-internal.h"

/* Frames whose timers may be in flight at once. */
#define TW_GPUTIME_RING 8

enum tw_gputime_mark {
    TW_GPUTIME_FRAME_BEGIN,     /* the timed frame */
    TW_GPUTIME_FRAME_END,
    TW_GPUTIME_ID_BEGIN,        /* the untimed ID pass */
    TW_GPUTIME_ID_END,
    TW_GPUTIME_MARKS
};

struct tw_gputime_entry {
    GLuint queries[TW_GPUTIME_MARKS];
    unsigned marked;            /* bit m: mark m issued for this frame */
    bool pending;               /* marked, not read yet */
    enum tw_method method;
    uint64_t frame;             /* the method's frame number */
    double ms, ms_id;           /* once read: -1 unknown; ms_id 0 without an ID pass */
};

/* The latest frame of a method whose timers came back. */
struct tw_gputime_late {
    uint64_t frame;             /* 0: none yet */
    double ms;
};

struct tw_gputime {
    const struct tw_gl *gl;     /* borrowed: the renderer's */
    bool on;                    /* the context counts time (GL_QUERY_COUNTER_BITS > 0) */
    bool created;               /* the query objects exist */
    struct tw_gputime_entry ring[TW_GPUTIME_RING];
    uint32_t next;              /* the entry the next frame takes */
    int32_t current;            /* the entry of the frame being drawn or last drawn;
                                   -1: none (no frame yet, or a fixed set's) */
    uint64_t dropped;           /* entries reused before their results came back */
    struct tw_gputime_late late[TW_METHOD_ALL];
};

/* Makes the query objects; the context of gl must be current. Without a
 * timestamp counter every time reads unknown. */
void tw_gputime_init(struct tw_gputime *t, const struct tw_gl *gl);
/* Deletes the query objects (the context current); accepts a zeroed t. */
void tw_gputime_finish(struct tw_gputime *t);

/* A frame of method m (its frame number frame) begins: reads, without
 * waiting, what earlier frames' timers have returned, then takes the next
 * entry (one still in flight is dropped). */
void tw_gputime_begin(struct tw_gputime *t, enum tw_method m, uint64_t frame);
/* Marks a pass boundary of the current frame in the GL command stream; a
 * begin mark is flushed at once (gputime.c says why). */
void tw_gputime_mark(struct tw_gputime *t, enum tw_gputime_mark mark);
/* No current frame: the next tw_gputime_current() reads nothing. */
void tw_gputime_forget(struct tw_gputime *t);
/* The current frame's times, if they have come back (after glFinish they
 * have): *ms the frame's, -1 unknown; *ms_id its ID pass's, 0 without
 * one, -1 unknown. Returns false (both untouched) with no current frame. */
bool tw_gputime_current(struct tw_gputime *t, double *ms, double *ms_id);
/* The latest frame of m read so far: *frame 0 and *ms -1 when none. */
void tw_gputime_late(const struct tw_gputime *t, enum tw_method m, uint64_t *frame, double *ms);

#endif
