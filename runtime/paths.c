/* Camera paths: the built-in ones and path CSV files (runtime.h). */
#include "tileworld/runtime.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char *const tw_path_builtin_names[] = {"street", "flyover", "forest", "teleport", "spin",
                                             NULL};

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

/* Eye height along the streets (the tile borders), turning at crossings. */
static int path_street(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d)
{
    static const int dx[4] = {0, 1, 0, -1}, dz[4] = {1, 0, -1, 0};
    const double speed = 1.0;       /* metres per frame */
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
                if (choice >= 2) {
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

/* Rises from the street to ~300 m while moving on, looking across the city
 * at grazing angles: little occlusion, many tiles. */
static int path_flyover(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d)
{
    const double yaw0 = 20.0 + (double)(tw_tiles_hash(seed, 7, 7) % 50);
    double x = 0.0, z = 0.0;
    for (uint32_t f = 0; f < frames; f++) {
        const double rise = smoothstep(f / 240.0);
        const double yaw = yaw0 + 0.08 * f;
        const double speed = 1.0 + 3.0 * rise;
        const double y = eye_height + (300.0 - eye_height) * rise;
        const double pitch = 2.0 - 14.0 * rise;
        if (set_key(&keys[f], x, y, z, yaw, pitch, w, d))
            return TW_ERR_INVALID;
        const double r = yaw * 3.14159265358979323846 / 180.0;
        x += sin(r) * speed;
        z += cos(r) * speed;
    }
    return TW_OK;
}

/* Eye height, wandering: heading drifts smoothly, not bound to streets. */
static int path_forest(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d)
{
    const double phase = (double)(tw_tiles_hash(seed, 3, 3) % 1000) / 1000.0 * 6.28318530718;
    double x = 0.37 * w, z = 0.41 * d;
    for (uint32_t f = 0; f < frames; f++) {
        const double yaw = 25.0 + 50.0 * sin(f / 90.0 + phase) + 20.0 * sin(f / 23.0);
        const double pitch = 2.0 * sin(f / 40.0);
        if (set_key(&keys[f], x, eye_height, z, yaw, pitch, w, d))
            return TW_ERR_INVALID;
        const double r = yaw * 3.14159265358979323846 / 180.0;
        x += sin(r) * 0.8;
        z += cos(r) * 0.8;
    }
    return TW_OK;
}

/* The street walk, but every 50 frames the camera jumps to an unrelated
 * place (a hashed cell far away, a random heading): temporal coherence
 * fails by design. */
static int path_teleport(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d)
{
    const uint32_t leg = 50;
    int err = path_street(seed, keys, frames, w, d);
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
static int path_spin(uint64_t seed, struct tw_camera *keys, uint32_t frames, float w, float d)
{
    const uint32_t period = 40, spin = 6;
    int err = path_street(seed, keys, frames, w, d);
    double extra = 0.0;
    for (uint32_t f = 0; f < frames && !err; f++) {
        const uint32_t t = f % period;
        if (f >= period && t < spin)
            extra += 180.0 / spin;
        keys[f].yaw = (float)fmod(keys[f].yaw + extra, 360.0);
    }
    return err;
}

int tw_path_builtin(const char *name, uint64_t seed, uint32_t frames, float w, float d,
                    struct tw_path *out)
{
    if (!name || !out || frames == 0 || !(w > 0.0f) || !(d > 0.0f))
        return TW_ERR_INVALID;
    int (*gen)(uint64_t, struct tw_camera *, uint32_t, float, float) = NULL;
    if (strcmp(name, "street") == 0)
        gen = path_street;
    else if (strcmp(name, "flyover") == 0)
        gen = path_flyover;
    else if (strcmp(name, "forest") == 0)
        gen = path_forest;
    else if (strcmp(name, "teleport") == 0)
        gen = path_teleport;
    else if (strcmp(name, "spin") == 0)
        gen = path_spin;
    else
        return TW_ERR_INVALID;
    memset(out, 0, sizeof(*out));
    out->keys = calloc(frames, sizeof(*out->keys));
    if (!out->keys)
        return TW_ERR_NOMEM;
    snprintf(out->name, sizeof(out->name), "%s", name);
    out->count = frames;
    int err = gen(seed, out->keys, frames, w, d);
    if (err)
        tw_path_finish(out);
    return err;
}

static int parse_row(char *line, double v[7], int64_t cell[2], char *why, size_t why_size)
{
    char *s = line;
    for (int k = 0; k < 7; k++) {
        while (*s == ' ' || *s == '\t')
            s++;
        char *end = NULL;
        errno = 0;
        if (k < 2) {
            long long c = strtoll(s, &end, 10);
            if (end == s || errno == ERANGE) {
                snprintf(why, why_size, "field %d (%s) is not a 64-bit integer", k + 1,
                         k == 0 ? "cell_i" : "cell_j");
                return TW_ERR_FORMAT;
            }
            cell[k] = c;
        } else {
            v[k] = strtod(s, &end);
            if (end == s || !isfinite(v[k]) || errno == ERANGE) {
                static const char *const names[] = {"", "", "x", "y", "z", "yaw", "pitch"};
                snprintf(why, why_size, "field %d (%s) is not a finite number", k + 1, names[k]);
                return TW_ERR_FORMAT;
            }
        }
        s = end;
        while (*s == ' ' || *s == '\t')
            s++;
        if (k < 6) {
            if (*s != ',') {
                snprintf(why, why_size, "expected 7 comma-separated fields, found %d", k + 1);
                return TW_ERR_FORMAT;
            }
            s++;
        }
    }
    while (*s == ' ' || *s == '\t' || *s == '\r' || *s == '\n')
        s++;
    if (*s != '\0') {
        snprintf(why, why_size, "unexpected text after the 7th field");
        return TW_ERR_FORMAT;
    }
    if (v[6] <= -89.9 || v[6] >= 89.9) {
        snprintf(why, why_size, "pitch %g is outside (-89.9, 89.9) degrees", v[6]);
        return TW_ERR_FORMAT;
    }
    if (fabs(v[2]) > 1e7 || fabs(v[3]) > 1e7 || fabs(v[4]) > 1e7) {
        snprintf(why, why_size, "a local offset exceeds 1e7 metres");
        return TW_ERR_FORMAT;
    }
    return TW_OK;
}

int tw_path_load_csv(const char *file, uint32_t frames, float w, float d, struct tw_path *out,
                     char *err, size_t err_size)
{
    memset(out, 0, sizeof(*out));
    FILE *f = fopen(file, "r");
    if (!f) {
        snprintf(err, err_size, "%s: cannot open: %s", file, strerror(errno));
        return TW_ERR_IO;
    }
    char line[1024];
    uint32_t cap = 0, lineno = 0;
    int rc = TW_OK;
    char why[160];
    bool header = false;
    while (fgets(line, sizeof(line), f)) {
        lineno++;
        if (!strchr(line, '\n') && !feof(f)) {
            snprintf(err, err_size, "%s:%u: line longer than %zu characters", file, lineno,
                     sizeof(line) - 2);
            rc = TW_ERR_FORMAT;
            goto out;
        }
        if (!header) {
            if (strncmp(line, "cell_i", 6) != 0) {
                snprintf(err, err_size,
                         "%s:%u: expected the header cell_i,cell_j,x,y,z,yaw,pitch", file, lineno);
                rc = TW_ERR_FORMAT;
                goto out;
            }
            header = true;
            continue;
        }
        if (line[strspn(line, " \t\r\n")] == '\0')
            continue;
        if (frames > 0 && out->count == frames)
            break;
        double v[7];
        int64_t cell[2];
        if (parse_row(line, v, cell, why, sizeof(why))) {
            snprintf(err, err_size, "%s:%u: %s", file, lineno, why);
            rc = TW_ERR_FORMAT;
            goto out;
        }
        if (out->count == cap) {
            cap = cap ? cap * 2 : 256;
            struct tw_camera *k = realloc(out->keys, sizeof(*k) * cap);
            if (!k) {
                rc = TW_ERR_NOMEM;
                goto out;
            }
            out->keys = k;
        }
        struct tw_camera *key = &out->keys[out->count];
        key->pos.cell.i = cell[0];
        key->pos.cell.j = cell[1];
        key->pos.local[0] = (float)v[2];
        key->pos.local[1] = (float)v[3];
        key->pos.local[2] = (float)v[4];
        key->yaw = (float)v[5];
        key->pitch = (float)v[6];
        if (tw_tiles_normalize(&key->pos, w, d)) {
            snprintf(err, err_size, "%s:%u: the position overflows the grid", file, lineno);
            rc = TW_ERR_FORMAT;
            goto out;
        }
        out->count++;
    }
    if (ferror(f)) {
        snprintf(err, err_size, "%s: read error", file);
        rc = TW_ERR_IO;
    } else if (!header) {
        snprintf(err, err_size, "%s: empty file (expected a header line)", file);
        rc = TW_ERR_FORMAT;
    } else if (out->count == 0) {
        snprintf(err, err_size, "%s: no camera rows after the header", file);
        rc = TW_ERR_FORMAT;
    } else if (frames > 0 && out->count < frames) {
        snprintf(err, err_size, "%s: %u frames asked for but the file has %u rows", file, frames,
                 out->count);
        rc = TW_ERR_FORMAT;
    }
out:
    fclose(f);
    if (rc) {
        tw_path_finish(out);
    } else {
        const char *base = strrchr(file, '/');
        snprintf(out->name, sizeof(out->name), "%s", base ? base + 1 : file);
    }
    return rc;
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
