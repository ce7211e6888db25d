/* Camera paths: the built-in ones and path CSV files (runtime.h). */
#include "runtime/runtime-internal.h"
#include "tiles/tiles-internal.h"
#include "tileworld/runtime.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

const char *const tw_path_builtin_names[] = {"street", "flyover", "forest", "teleport", "spin",
                                             "straight", "wander", NULL};

static const float eye_height = 1.7f;

static double smoothstep(double t)
{
    t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
    return t * t * (3.0 - 2.0 * t);
}

/* Positions are accumulated in double metres from the origin of cell (0, 0)
 * and only then split into cell + local: paths stay exact however long. */
static int set_key(struct tw_camera *key, double x, double y, double z, double yaw,
                   double pitch, float w, float d)
{
    key->pos.cell.i = 0;
    key->pos.cell.j = 0;
    key->pos.local[0] = (float)x;
    key->pos.local[1] = (float)y;
    key->pos.local[2] = (float)z;
    key->yaw = (float)fmod(yaw, 360.0);
    key->pitch = (float)pitch;
    return tw_tiles_normalize(&key->pos, w, d);
}

/* Eye height along the streets (the tile borders) at speed metres per
 * frame, turning at crossings when turns. */
static int walk_streets(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d,
                        double speed, bool turns)
{
    static const int dx[4] = {0, 1, 0, -1}, dz[4] = {1, 0, -1, 0};
    const uint32_t turn_frames = 16;
    double x = 0.0, z = 0.0;
    int dir = 0;                     /* 0: +z, 1: +x, 2: -z, 3: -x (yaw = 90 * dir) */
    double yaw = 0.0;
    uint32_t turning = 0;            /* frames left in the current turn */
    double turn_from = 0.0, turn_to = 0.0;
    double to_crossing = d;          /* metres left to the next crossing */
    uint64_t crossing = 0;
    for (uint32_t f = 0; f < frames; f++) {
        if (turning > 0) {
            const double t = 1.0 - (double)(turning - 1) / turn_frames;
            yaw = turn_from + (turn_to - turn_from) * smoothstep(t);
            turning--;
        } else {
            const double step = speed < to_crossing ? speed : to_crossing;
            x += dx[dir] * step;
            z += dz[dir] * step;
            to_crossing -= step;
            if (to_crossing <= 1e-9) {
                /* At a crossing: go on, or turn left or right. */
                const uint64_t h = tw_tiles_hash(seed, (int64_t)crossing++, 0x5757);
                const int choice = (int)(h % 4);          /* 0, 1: straight; 2: left; 3: right */
                if (turns && choice >= 2) {
                    const int turn = choice == 2 ? -1 : 1;
                    dir = (dir + 4 + turn) & 3;
                    turn_from = yaw;
                    turn_to = yaw + 90.0 * turn;
                    turning = turn_frames;
                }
                to_crossing = (dir & 1) ? w : d;
            }
        }
        if (set_key(&keys[f], x, eye_height, z, yaw, 2.0, w, d))
            return TW_ERR_INVALID;
    }
    return TW_OK;
}

static int path_street(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d,
                       double speed)
{
    return walk_streets(seed, keys, frames, w, d, speed > 0.0 ? speed : 1.0, true);
}

/* The long paths of the memory test: along one street, or wandering
 * through the streets (turns at crossings), at 2 m a frame by default. */
static int path_straight(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w,
                         float d, double speed)
{
    return walk_streets(seed, keys, frames, w, d, speed > 0.0 ? speed : 2.0, false);
}

static int path_wander(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d,
                       double speed)
{
    return walk_streets(seed, keys, frames, w, d, speed > 0.0 ? speed : 2.0, true);
}

/* Rises from the street to ~300 m while moving on, looking across the city
 * at grazing angles: little occlusion, many tiles. */
static int path_flyover(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d,
                        double speed)
{
    const double yaw0 = 20.0 + (double)(tw_tiles_hash(seed, 7, 7) % 50);
    double x = 0.0, z = 0.0;
    for (uint32_t f = 0; f < frames; f++) {
        const double rise = smoothstep(f / 240.0);
        const double yaw = yaw0 + 0.08 * f;
        const double pace = (speed > 0.0 ? speed : 1.0) * (1.0 + 3.0 * rise);
        const double y = eye_height + (300.0 - eye_height) * rise;
        const double pitch = 2.0 - 14.0 * rise;
        if (set_key(&keys[f], x, y, z, yaw, pitch, w, d))
            return TW_ERR_INVALID;
        const double r = yaw * 3.14159265358979323846 / 180.0;
        x += sin(r) * pace;
        z += cos(r) * pace;
    }
    return TW_OK;
}

/* Eye height, wandering: heading drifts smoothly, not bound to streets. */
static int path_forest(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d,
                       double speed)
{
    const double phase = (double)(tw_tiles_hash(seed, 3, 3) % 1000) / 1000.0 * 6.28318530718;
    double x = 0.37 * w, z = 0.41 * d;
    for (uint32_t f = 0; f < frames; f++) {
        const double yaw = 25.0 + 50.0 * sin(f / 90.0 + phase) + 20.0 * sin(f / 23.0);
        const double pitch = 2.0 * sin(f / 40.0);
        if (set_key(&keys[f], x, eye_height, z, yaw, pitch, w, d))
            return TW_ERR_INVALID;
        const double r = yaw * 3.14159265358979323846 / 180.0;
        x += sin(r) * (speed > 0.0 ? speed : 0.8);
        z += cos(r) * (speed > 0.0 ? speed : 0.8);
    }
    return TW_OK;
}

/* The street walk, but every 50 frames the camera jumps to an unrelated
 * place (a hashed cell far away, a random heading): temporal coherence
 * fails by design. */
static int path_teleport(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d,
                         double speed)
{
    const uint32_t leg = 50;
    int err = path_street(seed, keys, frames, w, d, speed);
    for (uint32_t f = leg; f < frames && !err; f++) {
        const uint32_t jump = f / leg;
        const uint64_t h = tw_tiles_hash(seed, (int64_t)jump, 0x7e1e);
        const int64_t di = (int64_t)(h % 20001) - 10000;
        const int64_t dj = (int64_t)((h >> 20) % 20001) - 10000;
        const float turn = 90.0f * (float)((h >> 40) % 4);
        keys[f].pos.cell.i += di;
        keys[f].pos.cell.j += dj;
        keys[f].yaw = (float)fmod(keys[f].yaw + turn, 360.0);
    }
    return err;
}

/* The street walk, with a 180-degree turn on the spot within 6 frames every
 * 40 frames. */
static int path_spin(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d,
                     double speed)
{
    const uint32_t period = 40, spin = 6;
    int err = path_street(seed, keys, frames, w, d, speed);
    double extra = 0.0;
    for (uint32_t f = 0; f < frames && !err; f++) {
        const uint32_t t = f % period;
        if (f >= period && t < spin)
            extra += 180.0 / spin;
        keys[f].yaw = (float)fmod(keys[f].yaw + extra, 360.0);
    }
    return err;
}

int tw_path_builtin(const char *name, uint64_t seed, uint32_t frames, float speed, float w,
                    float d, struct tw_path *out)
{
    if (!name || !out || frames == 0 || !(w > 0.0f) || !(d > 0.0f) ||
        !(speed >= 0.0f && speed <= 1000.0f))
        return TW_ERR_INVALID;
    static const struct {
        const char *name;
        int (*gen)(uint64_t, struct tw_camera *, uint32_t, float, float, double);
    } paths[] = {
        {"street", path_street},     {"flyover", path_flyover},   {"forest", path_forest},
        {"teleport", path_teleport}, {"spin", path_spin},         {"straight", path_straight},
        {"wander", path_wander},
    };
    int (*gen)(uint64_t, struct tw_camera *, uint32_t, float, float, double) = NULL;
    for (size_t k = 0; k < sizeof(paths) / sizeof(paths[0]) && !gen; k++)
        if (strcmp(name, paths[k].name) == 0)
            gen = paths[k].gen;
    if (!gen)
        return TW_ERR_INVALID;
    memset(out, 0, sizeof(*out));
    out->keys = calloc(frames, sizeof(*out->keys));
    if (!out->keys)
        return TW_ERR_NOMEM;
    snprintf(out->name, sizeof(out->name), "%s", name);
    out->count = frames;
    int err = gen(seed, out->keys, frames, w, d, speed);
    if (err)
        tw_path_finish(out);
    return err;
}

/* ---- path CSV files --------------------------------------------------------------- */

#define MAX_LINE 1022                  /* characters of a row, its newline excluded */
#define MAX_OFFSET 1.0e7               /* |x|, |z|: metres from the cell's origin */
#define MAX_YAW 1.0e6                  /* degrees (kept modulo 360) */
#define MAX_PITCH 89.9                 /* degrees, exclusive */

static const char *const field_names[7] = {"cell_i", "cell_j", "x", "y", "z", "yaw", "pitch"};

/* "field 3 (x) \"<text>\"": names a field and quotes it, escaped and cut. */
static void name_field(char *out, size_t size, int k, const char *text, size_t len)
{
    char quoted[48];
    tw_log_escape_bytes(text, len > 32 ? 32 : len, quoted, sizeof(quoted));
    snprintf(out, size, "field %d (%s) \"%s%s\"", k + 1, field_names[k], quoted,
             len > 32 ? "..." : "");
}

/* A decimal integer field: [+-]digits, within int64_t. */
static int parse_cell(const char *f, size_t len, int k, int64_t *out, char *why, size_t why_size)
{
    char what[128];
    name_field(what, sizeof(what), k, f, len);
    size_t p = 0;
    bool negative = false;
    if (p < len && (f[p] == '+' || f[p] == '-'))
        negative = f[p++] == '-';
    if (p == len) {
        snprintf(why, why_size, "%s is not a decimal integer", what);
        return TW_ERR_FORMAT;
    }
    uint64_t v = 0;
    const uint64_t limit = negative ? (uint64_t)INT64_MAX + 1 : (uint64_t)INT64_MAX;
    for (; p < len; p++) {
        if (f[p] < '0' || f[p] > '9') {
            snprintf(why, why_size, "%s is not a decimal integer%s", what,
                     (f[p] == 'x' || f[p] == 'X') ? " (hexadecimal is not accepted)"
                     : (f[p] == '.' || f[p] == 'e' || f[p] == 'E') ? " (a cell is a whole number)"
                                                                  : "");
            return TW_ERR_FORMAT;
        }
        const uint64_t digit = (uint64_t)(f[p] - '0');
        if (v > (limit - digit) / 10) {
            snprintf(why, why_size, "%s is beyond the 64-bit range of a cell", what);
            return TW_ERR_FORMAT;
        }
        v = v * 10 + digit;
    }
    *out = negative ? (int64_t)(0 - v) : (int64_t)v;
    return TW_OK;
}

/* A decimal number field: digits, '.', an exponent; finite, within
 * [lo, hi] (open at both ends when open). */
static int parse_number(const char *f, size_t len, int k, double lo, double hi, bool open,
                        const char *unit, double *out, char *why, size_t why_size)
{
    char what[128], text[64];
    name_field(what, sizeof(what), k, f, len);
    bool digits = false, other = len >= sizeof(text);
    for (size_t p = 0; p < len; p++) {
        const char c = f[p];
        digits |= c >= '0' && c <= '9';
        other |= !((c >= '0' && c <= '9') || c == '.' || c == 'e' || c == 'E' || c == '+' ||
                   c == '-');
    }
    if (!digits || other) {
        snprintf(why, why_size, "%s is not a decimal number", what);
        return TW_ERR_FORMAT;
    }
    memcpy(text, f, len);
    text[len] = '\0';
    char *end = NULL;
    errno = 0;
    const double v = strtod(text, &end);
    if (end != text + len) {
        snprintf(why, why_size, "%s is not a decimal number", what);
        return TW_ERR_FORMAT;
    }
    if (!isfinite(v) || v < lo || v > hi || (open && (v == lo || v == hi))) {
        snprintf(why, why_size, "%s is outside %s%g, %g%s %s", what, open ? "(" : "[", lo, hi,
                 open ? ")" : "]", unit);
        return TW_ERR_FORMAT;
    }
    *out = v;
    return TW_OK;
}

/* One row "cell_i,cell_j,x,y,z,yaw,pitch" of line[0, len) (no newline). */
static int parse_row(const char *line, size_t len, int64_t cell[2], double v[7], char *why,
                     size_t why_size)
{
    const char *field[7];
    size_t flen[7];
    int n = 0;
    size_t start = 0;
    for (size_t p = 0; p <= len; p++) {
        if (p < len && line[p] != ',')
            continue;
        if (n < 7) {
            size_t a = start, b = p;
            while (a < b && (line[a] == ' ' || line[a] == '\t'))
                a++;
            while (b > a && (line[b - 1] == ' ' || line[b - 1] == '\t' || line[b - 1] == '\r'))
                b--;
            field[n] = line + a;
            flen[n] = b - a;
        }
        n++;
        start = p + 1;
    }
    if (n != 7) {
        snprintf(why, why_size,
                 "expected 7 comma-separated fields (cell_i,cell_j,x,y,z,yaw,pitch), found %d", n);
        return TW_ERR_FORMAT;
    }
    for (int k = 0; k < 7; k++) {
        if (flen[k] == 0) {
            snprintf(why, why_size, "field %d (%s) is empty", k + 1, field_names[k]);
            return TW_ERR_FORMAT;
        }
    }
    int err;
    if ((err = parse_cell(field[0], flen[0], 0, &cell[0], why, why_size)) ||
        (err = parse_cell(field[1], flen[1], 1, &cell[1], why, why_size)) ||
        (err = parse_number(field[2], flen[2], 2, -MAX_OFFSET, MAX_OFFSET, false,
                            "metres from the cell's origin", &v[2], why, why_size)) ||
        (err = parse_number(field[3], flen[3], 3, -TW_TILES_MAX_COORD, TW_TILES_MAX_COORD,
                            false, "metres above the ground", &v[3], why, why_size)) ||
        (err = parse_number(field[4], flen[4], 4, -MAX_OFFSET, MAX_OFFSET, false,
                            "metres from the cell's origin", &v[4], why, why_size)) ||
        (err = parse_number(field[5], flen[5], 5, -MAX_YAW, MAX_YAW, false, "degrees", &v[5],
                            why, why_size)) ||
        (err = parse_number(field[6], flen[6], 6, -MAX_PITCH, MAX_PITCH, true, "degrees",
                            &v[6], why, why_size)))
        return err;
    return TW_OK;
}

/* The reader of a path CSV, fed one line at a time (from memory or as a
 * file is read): the first bad line ends it, before anything after it is
 * read. */
struct csv_reader {
    const char *shown;          /* the file name, escaped */
    uint32_t frames;            /* > 0: stop after this many rows */
    float w, d;
    struct tw_path *out;
    uint32_t cap, lineno;
    bool header;
    char *err;
    size_t err_size;
};

/* Line lineno of the file, line[0, len) without its newline. Returns 0 to go
 * on, 1 when the rows asked for are read (the rest need not be), or a
 * negative error (err written). */
static int feed_line(struct csv_reader *r, const char *line, size_t len)
{
    struct tw_path *out = r->out;
    r->lineno++;
    const char *nul = memchr(line, '\0', len);
    if (nul) {
        snprintf(r->err, r->err_size, "%s:%u: a NUL byte at column %zu: not a text file",
                 r->shown, r->lineno, (size_t)(nul - line) + 1);
        return TW_ERR_FORMAT;
    }
    if (len > (size_t)MAX_LINE + (len > 0 && line[len - 1] == '\r')) {
        snprintf(r->err, r->err_size, "%s:%u: line longer than %d characters", r->shown,
                 r->lineno, MAX_LINE);
        return TW_ERR_FORMAT;
    }
    if (!r->header) {
        if (len < 6 || strncmp(line, "cell_i", 6) != 0) {
            snprintf(r->err, r->err_size,
                     "%s:%u: expected the header cell_i,cell_j,x,y,z,yaw,pitch", r->shown,
                     r->lineno);
            return TW_ERR_FORMAT;
        }
        r->header = true;
        return TW_OK;
    }
    size_t blank = 0;
    while (blank < len && (line[blank] == ' ' || line[blank] == '\t' || line[blank] == '\r'))
        blank++;
    if (blank == len)
        return TW_OK;
    double v[7];
    int64_t cell[2];
    char why[256];
    if (parse_row(line, len, cell, v, why, sizeof(why))) {
        snprintf(r->err, r->err_size, "%s:%u: %s", r->shown, r->lineno, why);
        return TW_ERR_FORMAT;
    }
    if (out->count == r->cap) {
        if (r->cap >= TW_PATH_MAX_ROWS) {
            snprintf(r->err, r->err_size,
                     "%s:%u: more than %u camera rows, the most frames a path may have",
                     r->shown, r->lineno, TW_PATH_MAX_ROWS);
            return TW_ERR_LIMIT;
        }
        uint32_t cap = r->cap ? 2 * r->cap : 256;
        if (cap > TW_PATH_MAX_ROWS)
            cap = TW_PATH_MAX_ROWS;
        struct tw_camera *k = realloc(out->keys, sizeof(*k) * cap);
        if (!k) {
            snprintf(r->err, r->err_size, "%s:%u: out of memory", r->shown, r->lineno);
            return TW_ERR_NOMEM;
        }
        out->keys = k;
        r->cap = cap;
    }
    struct tw_camera *key = &out->keys[out->count];
    const double local[3] = {v[2], v[3], v[4]};
    const struct tw_cell c = {cell[0], cell[1]};
    if (tw_tiles_normalize_double(c, local, r->w, r->d, &key->pos)) {
        snprintf(r->err, r->err_size,
                 "%s:%u: the position overflows the grid (cell plus offset beyond 64 bits)",
                 r->shown, r->lineno);
        return TW_ERR_FORMAT;
    }
    key->yaw = (float)fmod(v[5], 360.0);
    key->pitch = (float)v[6];
    out->count++;
    return r->frames > 0 && out->count == r->frames ? 1 : TW_OK;
}

/* Sets r up for out, or writes why not (a caller's bug). */
static int reader_begin(struct csv_reader *r, const char *name, uint32_t frames, float w, float d,
                        struct tw_path *out, char *shown, size_t shown_size, char *err,
                        size_t err_size)
{
    memset(r, 0, sizeof(*r));
    r->err = err;
    r->err_size = err_size;
    err[0] = '\0';
    if (!out) {
        snprintf(err, err_size, "path: out is NULL (caller's bug)");
        return TW_ERR_INVALID;
    }
    memset(out, 0, sizeof(*out));
    tw_log_escape(name ? name : "(path)", shown, shown_size);
    if (!(w > 0.0f) || !(d > 0.0f) || !isfinite(w) || !isfinite(d) ||
        frames > TW_PATH_MAX_ROWS) {
        snprintf(err, err_size, "%s: invalid arguments (caller's bug)", shown);
        return TW_ERR_INVALID;
    }
    r->shown = shown;
    r->frames = frames;
    r->w = w;
    r->d = d;
    r->out = out;
    return TW_OK;
}

/* After the last line (rc: what feeding ended with): the checks of the
 * whole file, then the path's name, or the path freed on error. */
static int reader_end(struct csv_reader *r, int rc, const char *name)
{
    struct tw_path *out = r->out;
    if (rc > 0)
        rc = TW_OK;
    else if (!rc && !r->header) {
        snprintf(r->err, r->err_size, "%s: empty file (expected a header line)", r->shown);
        rc = TW_ERR_FORMAT;
    } else if (!rc && out->count == 0) {
        snprintf(r->err, r->err_size, "%s: no camera rows after the header", r->shown);
        rc = TW_ERR_FORMAT;
    } else if (!rc && r->frames > 0 && out->count < r->frames) {
        snprintf(r->err, r->err_size, "%s: %u frames asked for but the file has %u rows",
                 r->shown, r->frames, out->count);
        rc = TW_ERR_FORMAT;
    }
    if (rc) {
        tw_path_finish(out);
    } else {
        const char *n = name ? name : "(path)";
        const char *base = strrchr(n, '/');
        tw_log_escape(base ? base + 1 : n, out->name, sizeof(out->name));
    }
    return rc;
}

int tw_path_parse_csv(const char *text, size_t size, const char *name, uint32_t frames, float w,
                      float d, struct tw_path *out, char *err, size_t err_size)
{
    char shown[256];
    char dummy[1];
    if (!err || err_size == 0) {
        err = dummy;
        err_size = sizeof(dummy);
    }
    struct csv_reader r;
    int rc = reader_begin(&r, name, frames, w, d, out, shown, sizeof(shown), err, err_size);
    if (rc)
        return rc;
    if (!text && size) {
        snprintf(err, err_size, "%s: invalid arguments (caller's bug)", shown);
        return TW_ERR_INVALID;
    }
    size_t pos = 0;
    /* A UTF-8 byte order mark before the header is not text. */
    if (size >= 3 && memcmp(text, "\xef\xbb\xbf", 3) == 0)
        pos = 3;
    while (pos < size && !rc) {
        const char *line = text + pos;
        const char *nl = memchr(line, '\n', size - pos);
        const size_t len = nl ? (size_t)(nl - line) : size - pos;
        pos += len + (nl ? 1 : 0);
        rc = feed_line(&r, line, len);
    }
    return reader_end(&r, rc, name);
}

/* Opens the regular file at path for reading (non-blocking: a FIFO or a
 * device is refused instead of waited on) and checks its size against
 * limit before anything is read. */
static int open_regular_file(const char *path, uint64_t limit, int *out_fd, char *why,
                             size_t why_size)
{
    *out_fd = -1;
    const int fd = open(path, O_RDONLY | O_NONBLOCK | O_NOCTTY | O_CLOEXEC);
    if (fd < 0) {
        if (errno == ENOENT)
            snprintf(why, why_size, "no such file");
        else
            snprintf(why, why_size, "cannot open: %s", strerror(errno));
        return TW_ERR_IO;
    }
    struct stat st;
    if (fstat(fd, &st) != 0) {
        snprintf(why, why_size, "cannot stat: %s", strerror(errno));
        close(fd);
        return TW_ERR_IO;
    }
    if (!S_ISREG(st.st_mode)) {
        snprintf(why, why_size, "is not a regular file (a %s)",
                 S_ISFIFO(st.st_mode) ? "FIFO" : S_ISDIR(st.st_mode) ? "folder"
                 : S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) ? "device" : S_ISSOCK(st.st_mode)
                 ? "socket" : "special file");
        close(fd);
        return TW_ERR_IO;
    }
    if (st.st_size < 0 || (uint64_t)st.st_size > limit) {
        snprintf(why, why_size, "is %lld bytes, more than the limit of %llu", (long long)st.st_size,
                 (unsigned long long)limit);
        close(fd);
        return TW_ERR_LIMIT;
    }
    *out_fd = fd;
    return TW_OK;
}

int tw_path_load_csv(const char *file, uint32_t frames, float w, float d, struct tw_path *out,
                     char *err, size_t err_size)
{
    char dummy[1];
    if (!err || err_size == 0) {
        err = dummy;
        err_size = sizeof(dummy);
    }
    if (!out || !file) {
        snprintf(err, err_size, "path: %s is NULL (caller's bug)", out ? "file" : "out");
        return TW_ERR_INVALID;
    }
    char shown[256], why[256];
    struct csv_reader r;
    int rc = reader_begin(&r, file, frames, w, d, out, shown, sizeof(shown), err, err_size);
    if (rc)
        return rc;
    int fd = -1;
    if ((rc = open_regular_file(file, TW_PATH_MAX_CSV_BYTES, &fd, why, sizeof(why)))) {
        snprintf(err, err_size, "%s: %s", shown, why);
        return rc;
    }
    /* Read in blocks, a line at a time: a bad row ends the reading there,
     * and so do the rows asked for. A line is at most MAX_LINE characters
     * and a \r, so a block always holds a whole one. */
    enum { BLOCK = 1 << 16 };
    char *buf = malloc(BLOCK);
    if (!buf) {
        close(fd);
        snprintf(err, err_size, "%s: out of memory", shown);
        return reader_end(&r, TW_ERR_NOMEM, file);
    }
    size_t have = 0;
    uint64_t total = 0;
    bool eof = false, bom_checked = false;
    for (;;) {
        if (!eof && have < BLOCK) {
            const ssize_t n = read(fd, buf + have, BLOCK - have);
            if (n < 0 && errno == EINTR)
                continue;
            if (n < 0) {
                snprintf(err, err_size, "%s: cannot read: %s", shown, strerror(errno));
                rc = TW_ERR_IO;
                break;
            }
            eof = n == 0;
            have += (size_t)n;
            total += (uint64_t)n;
            if (total > TW_PATH_MAX_CSV_BYTES) {
                snprintf(err, err_size, "%s: grew beyond the limit of %llu bytes while read",
                         shown, (unsigned long long)TW_PATH_MAX_CSV_BYTES);
                rc = TW_ERR_LIMIT;
                break;
            }
            /* A UTF-8 byte order mark before the header is not text. */
            if (!bom_checked && (have >= 3 || eof)) {
                bom_checked = true;
                if (have >= 3 && memcmp(buf, "\xef\xbb\xbf", 3) == 0) {
                    memmove(buf, buf + 3, have - 3);
                    have -= 3;
                }
            }
            if (!eof && have < BLOCK && (!bom_checked || !memchr(buf, '\n', have)))
                continue;
        }
        /* Whole lines of buf[0, have); a last one without its newline only
         * at the end of the file (or when it is too long already). */
        size_t pos = 0;
        while (!rc && pos < have) {
            const char *line = buf + pos;
            const char *nl = memchr(line, '\n', have - pos);
            if (!nl && !eof && have - pos <= (size_t)MAX_LINE + 1)
                break;
            const size_t len = nl ? (size_t)(nl - line) : have - pos;
            pos += len + (nl ? 1 : 0);
            rc = feed_line(&r, line, len);
        }
        memmove(buf, buf + pos, have - pos);
        have -= pos;
        if (rc || (eof && have == 0))
            break;
    }
    free(buf);
    close(fd);
    return reader_end(&r, rc, file);
}

int tw_path_translate(struct tw_path *p, int64_t di, int64_t dj)
{
    for (uint32_t k = 0; k < p->count; k++) {
        const struct tw_cell c = p->keys[k].pos.cell;
        if ((di > 0 && c.i > INT64_MAX - di) || (di < 0 && c.i < INT64_MIN - di) ||
            (dj > 0 && c.j > INT64_MAX - dj) || (dj < 0 && c.j < INT64_MIN - dj))
            return TW_ERR_INVALID;
    }
    for (uint32_t k = 0; k < p->count; k++) {
        p->keys[k].pos.cell.i += di;
        p->keys[k].pos.cell.j += dj;
    }
    return TW_OK;
}

void tw_path_finish(struct tw_path *p)
{
    if (!p)
        return;
    free(p->keys);
    p->keys = NULL;
    p->count = 0;
}
