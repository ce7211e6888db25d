/* Errors, logging, boxes, grid math and selection (tiles.h). */
#include "tiles/tiles-internal.h"
#include "tileworld/tiles.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

const char *tw_error_to_str(int err)
{
    switch (err) {
    case TW_OK: return "success";
    case TW_ERR_INVALID: return "invalid argument or input";
    case TW_ERR_NOMEM: return "out of memory";
    case TW_ERR_IO: return "input/output error";
    case TW_ERR_FORMAT: return "malformed file";
    case TW_ERR_LIMIT: return "input exceeds a configured limit";
    case TW_ERR_GL: return "OpenGL error";
    case TW_ERR_EMBREE: return "Embree error";
    case TW_ERR_STATE: return "invalid state";
    default: return "unknown error";
    }
}

void tw_log_vprintf(const struct tw_log *log, enum tw_log_level level,
                    const char *fmt, va_list ap)
{
    if (!log || !log->fn)
        return;
    char buf[1024], safe[1024];
    vsnprintf(buf, sizeof(buf), fmt, ap);
    /* One line of plain text whatever the pieces held (idempotent on text
     * that was escaped already). */
    log->fn(log->user, level, tw_log_escape(buf, safe, sizeof(safe)));
}

void tw_log_printf(const struct tw_log *log, enum tw_log_level level,
                   const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    tw_log_vprintf(log, level, fmt, ap);
    va_end(ap);
}

void tw_log_stderr(void *user, enum tw_log_level level, const char *msg)
{
    static const char *const names[] = {"error", "warning", "info", "debug"};
    if ((intptr_t)level > (intptr_t)user)
        return;
    fprintf(stderr, "tileworld: %s: %s\n", names[level], msg);
}

/* ---- escaping ---------------------------------------------------------------- */

/* The length of the valid UTF-8 sequence at s[0, n) and its code point, or 0
 * if it is not one (overlong forms, surrogates and values above U+10FFFF are
 * not). */
static size_t utf8_sequence(const unsigned char *s, size_t n, uint32_t *cp)
{
    size_t len;
    uint32_t v, min;
    if (s[0] >= 0xc2 && s[0] <= 0xdf) {
        len = 2; v = s[0] & 0x1fu; min = 0x80;
    } else if (s[0] >= 0xe0 && s[0] <= 0xef) {
        len = 3; v = s[0] & 0x0fu; min = 0x800;
    } else if (s[0] >= 0xf0 && s[0] <= 0xf4) {
        len = 4; v = s[0] & 0x07u; min = 0x10000;
    } else {
        return 0;
    }
    if (len > n)
        return 0;
    for (size_t k = 1; k < len; k++) {
        if ((s[k] & 0xc0) != 0x80)
            return 0;
        v = v << 6 | (s[k] & 0x3fu);
    }
    if (v < min || v > 0x10ffff || (v >= 0xd800 && v <= 0xdfff))
        return 0;
    *cp = v;
    return len;
}

static bool dangerous_code_point(uint32_t cp)
{
    return (cp >= 0x80 && cp <= 0x9f) || (cp >= 0x202a && cp <= 0x202e) ||
           (cp >= 0x2066 && cp <= 0x2069);
}

/* tw_log_escape_bytes(), with backslashes doubled when backslash is set. */
static const char *escape_bytes(const void *data, size_t n, bool backslash, char *out,
                                size_t size)
{
    if (!out || size == 0)
        return out;
    const unsigned char *s = data ? data : (const unsigned char *)"";
    if (!data)
        n = 0;
    /* A cut text ends with "...": cut is the end of the last piece that
     * leaves room for it. */
    const size_t room = size > 4 ? size - 4 : 0;
    size_t o = 0, cut = 0, k = 0;
    bool truncated = false;
    while (k < n) {
        char piece[8];
        size_t len = 0, used = 1;
        const unsigned char c = s[k];
        uint32_t cp = 0;
        if (c == '\\' && backslash) {
            piece[0] = piece[1] = '\\';
            len = 2;
        } else if (c >= 0x20 && c < 0x7f) {
            piece[0] = (char)c;
            len = 1;
        } else if (c == '\n' || c == '\r' || c == '\t') {
            piece[0] = '\\';
            piece[1] = c == '\n' ? 'n' : c == '\r' ? 'r' : 't';
            len = 2;
        } else if (c >= 0x80 && (used = utf8_sequence(s + k, n - k, &cp)) > 0) {
            if (dangerous_code_point(cp)) {
                len = (size_t)snprintf(piece, sizeof(piece), "\\u%04x", (unsigned)cp);
            } else {
                memcpy(piece, s + k, used);
                len = used;
            }
        } else {
            used = 1;
            len = (size_t)snprintf(piece, sizeof(piece), "\\x%02x", (unsigned)c);
        }
        if (o + len > size - 1) {
            truncated = true;
            break;
        }
        memcpy(out + o, piece, len);
        o += len;
        if (o <= room)
            cut = o;
        k += used;
    }
    if (truncated) {
        const size_t dots = size - 1 - cut < 3 ? size - 1 - cut : 3;
        memcpy(out + cut, "...", dots);
        o = cut + dots;
    }
    out[o] = '\0';
    return out;
}

const char *tw_log_escape_bytes(const void *data, size_t n, char *out, size_t size)
{
    return escape_bytes(data, n, false, out, size);
}

const char *tw_log_escape(const char *text, char *out, size_t size)
{
    return escape_bytes(text, text ? strlen(text) : 0, false, out, size);
}

const char *tw_log_escape_reversible(const char *text, char *out, size_t size)
{
    return escape_bytes(text, text ? strlen(text) : 0, true, out, size);
}

/* ---- boxes ----------------------------------------------------------------- */

struct tw_box tw_box_empty(void)
{
    struct tw_box b = {{FLT_MAX, FLT_MAX, FLT_MAX}, {-FLT_MAX, -FLT_MAX, -FLT_MAX}};
    return b;
}

bool tw_box_is_empty(const struct tw_box *b)
{
    return b->min[0] > b->max[0] || b->min[1] > b->max[1] || b->min[2] > b->max[2];
}

uint64_t tw_hash_more(uint64_t h, const void *p, uint64_t n)
{
    const uint8_t *b = p;
    for (uint64_t k = 0; k < n; k++)
        h = (h ^ b[k]) * 0x100000001b3ull;
    return h;
}

uint64_t tw_hash_bytes(const uint8_t *p, uint64_t n)
{
    return tw_hash_more(TW_HASH_START, p, n);
}

void tw_box_add_point(struct tw_box *b, const float p[3])
{
    for (int k = 0; k < 3; k++) {
        if (p[k] < b->min[k]) b->min[k] = p[k];
        if (p[k] > b->max[k]) b->max[k] = p[k];
    }
}

void tw_box_add_box(struct tw_box *b, const struct tw_box *o)
{
    if (tw_box_is_empty(o))
        return;
    tw_box_add_point(b, o->min);
    tw_box_add_point(b, o->max);
}

struct tw_box tw_box_transform(const struct tw_box *b, const float m[12])
{
    struct tw_box r = tw_box_empty();
    if (tw_box_is_empty(b))
        return r;
    for (int c = 0; c < 8; c++) {
        const float p[3] = {
            (c & 1) ? b->max[0] : b->min[0],
            (c & 2) ? b->max[1] : b->min[1],
            (c & 4) ? b->max[2] : b->min[2],
        };
        float q[3];
        for (int k = 0; k < 3; k++)
            q[k] = m[4 * k] * p[0] + m[4 * k + 1] * p[1] + m[4 * k + 2] * p[2] + m[4 * k + 3];
        tw_box_add_point(&r, q);
    }
    return r;
}

float tw_box_surface_area(const struct tw_box *b)
{
    if (tw_box_is_empty(b))
        return 0.0f;
    const float dx = b->max[0] - b->min[0];
    const float dy = b->max[1] - b->min[1];
    const float dz = b->max[2] - b->min[2];
    return 2.0f * (dx * dy + dy * dz + dz * dx);
}

/* ---- cells -------------------------------------------------------------------- */

int64_t tw_tiles_floor_div(int64_t a, int64_t b)
{
    int64_t q = a / b;
    if ((a % b != 0) && ((a < 0) != (b < 0)))
        q--;
    return q;
}

int64_t tw_tiles_floor_mod(int64_t a, int64_t b)
{
    int64_t r = a % b;
    if (r != 0 && ((r < 0) != (b < 0)))
        r += b;
    return r;
}

/* Splits a finite offset into whole footprints and a remainder in [0, size).
 * The quotient is range-checked in double before it becomes an int64_t:
 * converting an out-of-range double is undefined behaviour. */
static int split_axis(double v, double size, int64_t *cells, float *rest)
{
    if (!isfinite(v) || !isfinite(size) || !(size > 0.0))
        return TW_ERR_INVALID;
    double n = floor(v / size);
    if (!(fabs(n) < 9.0e18))
        return TW_ERR_INVALID;
    double r = v - n * size;
    if (!isfinite(r))
        return TW_ERR_INVALID;
    float rf = (float)r;
    /* Rounding can land exactly on size (or slightly below 0). */
    if (rf >= (float)size) { rf = 0.0f; n += 1.0; }
    if (rf < 0.0f) { rf = 0.0f; }
    *cells = (int64_t)n;
    *rest = rf;
    return TW_OK;
}

static bool add_overflows(int64_t a, int64_t b)
{
    return (b > 0 && a > INT64_MAX - b) || (b < 0 && a < INT64_MIN - b);
}

int tw_tiles_normalize(struct tw_world_pos *p, float w, float d)
{
    if (!p)
        return TW_ERR_INVALID;
    const double local[3] = {p->local[0], p->local[1], p->local[2]};
    return tw_tiles_normalize_double(p->cell, local, w, d, p);
}

int tw_tiles_normalize_double(struct tw_cell cell, const double local[3], float w, float d,
                              struct tw_world_pos *out)
{
    if (!out || !local || !isfinite(w) || !isfinite(d) || !(w > 0.0f) || !(d > 0.0f) ||
        !isfinite(local[0]) || !isfinite(local[1]) || !isfinite(local[2]) ||
        !(fabs(local[1]) <= FLT_MAX))
        return TW_ERR_INVALID;
    int64_t ci, cj;
    float x, z;
    if (split_axis(local[0], w, &ci, &x) || split_axis(local[2], d, &cj, &z))
        return TW_ERR_INVALID;
    if (add_overflows(cell.i, ci) || add_overflows(cell.j, cj))
        return TW_ERR_INVALID;
    out->cell.i = cell.i + ci;
    out->cell.j = cell.j + cj;
    out->local[0] = x;
    out->local[1] = (float)local[1];
    out->local[2] = z;
    return TW_OK;
}

double tw_tiles_cells_in_reach(const struct tw_box *common_box, float w, float d,
                               float view_distance)
{
    if (!common_box || tw_box_is_empty(common_box) || !(w > 0.0f) || !(d > 0.0f) ||
        !(view_distance >= 0.0f))
        return INFINITY;
    const double r2 = 2.0 * (double)view_distance;
    const double ni = (r2 + ((double)common_box->max[0] - common_box->min[0])) / w + 2.0;
    const double nj = (r2 + ((double)common_box->max[2] - common_box->min[2])) / d + 2.0;
    const double n = ni * nj;
    return isfinite(n) ? n : INFINITY;
}

void tw_tiles_cell_offset(struct tw_cell cell, struct tw_cell origin, float w,
                          float d, float out[3])
{
    /* Wrapping subtraction in uint64_t: the true difference of two cells in
     * view is small, whatever their magnitude. */
    const int64_t di = (int64_t)((uint64_t)cell.i - (uint64_t)origin.i);
    const int64_t dj = (int64_t)((uint64_t)cell.j - (uint64_t)origin.j);
    out[0] = (float)((double)di * (double)w);
    out[1] = 0.0f;
    out[2] = (float)((double)dj * (double)d);
}

/* ---- selection ------------------------------------------------------------------ */

static uint64_t splitmix64(uint64_t x)
{
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

uint64_t tw_tiles_hash(uint64_t seed, int64_t i, int64_t j)
{
    uint64_t h = splitmix64(seed);
    h = splitmix64(h ^ (uint64_t)i);
    h = splitmix64(h ^ ((uint64_t)j * 0xd6e8feb86659fd93ull));
    return h;
}

uint32_t tw_tiles_select(const struct tw_tileset *ts,
                         const struct tw_selection *sel, struct tw_cell cell)
{
    static const struct tw_selection defaults = {0};
    if (!sel)
        sel = &defaults;
    if (sel->repeat > 0) {
        cell.i = tw_tiles_floor_mod(cell.i, sel->repeat);
        cell.j = tw_tiles_floor_mod(cell.j, sel->repeat);
    }
    if (sel->fn)
        return sel->fn(sel->user, cell);   /* checked by the caller: an error, not a modulo */
    double total = 0.0;
    for (uint32_t k = 0; k < ts->prototype_count; k++)
        total += ts->prototypes[k].weight;
    /* 53 random bits -> [0, 1). */
    const double u = (double)(tw_tiles_hash(sel->seed, cell.i, cell.j) >> 11) * 0x1.0p-53;
    double target = u * total, acc = 0.0;
    for (uint32_t k = 0; k < ts->prototype_count; k++) {
        acc += ts->prototypes[k].weight;
        if (target < acc)
            return k;
    }
    return ts->prototype_count - 1;
}
