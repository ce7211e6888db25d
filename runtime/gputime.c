/* GPU time of frames from timestamp queries, never waited on (gputime.h). */
#include "runtime/gputime.h"

#include <string.h>

#define MARK(m) (1u << (m))
#define ID_MARKS (MARK(TW_GPUTIME_ID_BEGIN) | MARK(TW_GPUTIME_ID_END))

void tw_gputime_init(struct tw_gputime *t, const struct tw_gl *gl)
{
    memset(t, 0, sizeof(*t));
    t->gl = gl;
    t->current = -1;
    for (int m = 0; m < TW_METHOD_ALL; m++)
        t->late[m].ms = -1.0;
    /* A core 3.3 context has GL_TIMESTAMP, but may count with no bits. */
    GLint bits = 0;
    gl->GetQueryiv(GL_TIMESTAMP, GL_QUERY_COUNTER_BITS, &bits);
    t->on = bits > 0;
    if (!t->on)
        return;
    GLuint names[TW_GPUTIME_RING * TW_GPUTIME_MARKS];
    gl->GenQueries(TW_GPUTIME_RING * TW_GPUTIME_MARKS, names);
    for (int k = 0; k < TW_GPUTIME_RING; k++)
        memcpy(t->ring[k].queries, &names[k * TW_GPUTIME_MARKS], sizeof(t->ring[k].queries));
    t->created = true;
}

void tw_gputime_finish(struct tw_gputime *t)
{
    if (!t->created)
        return;
    for (int k = 0; k < TW_GPUTIME_RING; k++)
        t->gl->DeleteQueries(TW_GPUTIME_MARKS, t->ring[k].queries);
    t->created = false;
}

/* Milliseconds from mark a to mark b of stamps; -1 when either is missing. */
static double span(const GLuint64 *stamps, unsigned marked, int a, int b)
{
    if (!(marked & MARK(a)) || !(marked & MARK(b)) || stamps[b] < stamps[a])
        return -1.0;
    return (double)(stamps[b] - stamps[a]) * 1e-6;
}

/* Reads e if every mark of it has come back; false, untouched, if not. */
static bool read_entry(struct tw_gputime *t, struct tw_gputime_entry *e)
{
    const struct tw_gl *gl = t->gl;
    for (int m = 0; m < TW_GPUTIME_MARKS; m++) {
        if (!(e->marked & MARK(m)))
            continue;
        GLuint available = GL_FALSE;
        gl->GetQueryObjectuiv(e->queries[m], GL_QUERY_RESULT_AVAILABLE, &available);
        if (!available)
            return false;
    }
    GLuint64 stamps[TW_GPUTIME_MARKS] = {0};
    for (int m = 0; m < TW_GPUTIME_MARKS; m++)
        if (e->marked & MARK(m))
            gl->GetQueryObjectui64v(e->queries[m], GL_QUERY_RESULT, &stamps[m]);
    e->ms = span(stamps, e->marked, TW_GPUTIME_FRAME_BEGIN, TW_GPUTIME_FRAME_END);
    e->ms_id = e->marked & ID_MARKS ? span(stamps, e->marked, TW_GPUTIME_ID_BEGIN, TW_GPUTIME_ID_END)
                                    : 0.0;
    e->pending = false;
    struct tw_gputime_late *late = &t->late[e->method];
    if (e->ms >= 0.0 && e->frame > late->frame) {
        late->frame = e->frame;
        late->ms = e->ms;
    }
    return true;
}

void tw_gputime_begin(struct tw_gputime *t, enum tw_method m, uint64_t frame)
{
    if (!t->on) {
        t->current = -1;
        return;
    }
    /* A frame that failed midway has no end: nothing to read. */
    if (t->current >= 0 && !(t->ring[t->current].marked & MARK(TW_GPUTIME_FRAME_END)))
        t->ring[t->current].pending = false;
    /* Oldest first; the GPU finishes them in order, so the first still out
     * ends the look. */
    for (uint32_t k = 0; k < TW_GPUTIME_RING; k++) {
        struct tw_gputime_entry *e = &t->ring[(t->next + k) % TW_GPUTIME_RING];
        if (e->pending && !read_entry(t, e))
            break;
    }
    struct tw_gputime_entry *e = &t->ring[t->next];
    if (e->pending)
        t->dropped++;
    e->pending = true;
    e->marked = 0;
    e->method = m;
    e->frame = frame;
    e->ms = e->ms_id = -1.0;
    t->current = (int32_t)t->next;
    t->next = (t->next + 1) % TW_GPUTIME_RING;
}

void tw_gputime_mark(struct tw_gputime *t, enum tw_gputime_mark mark)
{
    if (t->current < 0)
        return;
    struct tw_gputime_entry *e = &t->ring[t->current];
    t->gl->QueryCounter(e->queries[mark], GL_TIMESTAMP);
    e->marked |= MARK(mark);
    /* llvmpipe stamps a timestamp in every tile of the batch it lands in and
     * reports the last tile's: a begin mark sent alone is stamped when the
     * work before it is done, not when the pass's first batch is. */
    if (mark == TW_GPUTIME_FRAME_BEGIN || mark == TW_GPUTIME_ID_BEGIN)
        t->gl->Flush();
}

void tw_gputime_forget(struct tw_gputime *t)
{
    t->current = -1;
}

bool tw_gputime_current(struct tw_gputime *t, double *ms, double *ms_id)
{
    if (t->current < 0)
        return false;
    struct tw_gputime_entry *e = &t->ring[t->current];
    if (e->pending && !read_entry(t, e)) {
        *ms = -1.0;
        *ms_id = e->marked & ID_MARKS ? -1.0 : 0.0;
        return true;
    }
    *ms = e->ms;
    *ms_id = e->ms_id;
    return true;
}

void tw_gputime_late(const struct tw_gputime *t, enum tw_method m, uint64_t *frame, double *ms)
{
    *frame = 0;
    *ms = -1.0;
    if ((unsigned)m < TW_METHOD_ALL && t->late[m].frame > 0) {
        *frame = t->late[m].frame;
        *ms = t->late[m].ms;
    }
}
