/* Charts of a bench run through gnuplot (charts.h). */
#include "tools/tileworld/charts.h"

#include <ctype.h>
#include <errno.h>
#include <fcntl.h>
#include <json-c/json.h>
#include <math.h>
#include <poll.h>
#include <stdarg.h>
#include <signal.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "tileworld/tiles.h"

#define MAX_METHODS 16
#define MAX_NAME 64
#define MAX_FIELDS 256
/* A sweep is methods x settings; far more would not be readable anyway. */
#define MAX_SWEEP_ROWS 4096
#define PATH_SIZE 4096
/* A chart run takes a second or two; this only stops a wedged gnuplot. */
#define GNUPLOT_TIMEOUT_S 120

/* Fixed colours for the known methods, so a method looks the same in every
 * chart of every run; other names take the free slots in order. vfc is the
 * grey baseline, the oracle a black dashed lower bound. */
static const char *const palette[MAX_METHODS] = {
    "#7f7f7f", "#56b4e9", "#009e73", "#d55e00", "#000000", "#0072b2", "#cc79a7", "#e69f00",
    "#882255", "#44aa99", "#999933", "#aa4499", "#661100", "#6699cc", "#117733", "#332288",
};
static const char *const known_methods[] = {"vfc", "tilequery", "chc", "tilequery+chc", "oracle"};

struct method {
    char name[MAX_NAME];
    char data_file[MAX_NAME + 32]; /* relative to dir */
    FILE *data;
    int colour;                    /* palette slot; gnuplot linetype colour + 1 */
    uint64_t frames;
    double ms_sum, triangles_sum, overdraw_sum, missed_total;
    double ms_min, ms_max, triangles_min, triangles_max; /* over frames, for log axes */
};

struct sweep_row {
    char method[MAX_NAME], param[MAX_NAME], value[MAX_NAME];
    int method_index;
    double x;                      /* the value, or its rank when by_rank */
    bool by_rank;                  /* the param is plotted by rank, values as tic labels */
    bool unaffected;               /* the param changes nothing this method draws */
    double mean_ms, missed_total, mean_overdraw;
    double mean_triangles;         /* -1 when sweep.csv has no mean_triangles */
};

struct charts {
    const char *dir;
    char *err;
    size_t err_size;
    struct method methods[MAX_METHODS];
    int method_count;
    bool accuracy_columns;         /* frames.csv has missed_pixels and overdraw_triangles */
    struct sweep_row *sweep;
    size_t sweep_count, sweep_cap;
    char subtitle[768];
};

/* A line of a CSV file split in place into fields. */
struct csv {
    FILE *f;
    char file[PATH_SIZE];
    char *line;
    size_t line_cap;
    unsigned long line_no;
    char *fields[MAX_FIELDS];
    int field_count;
};

static void set_error(struct charts *c, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static void set_error(struct charts *c, const char *fmt, ...)
{
    if (!c->err || c->err_size == 0)
        return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(c->err, c->err_size, fmt, ap);
    va_end(ap);
    /* The caller prints one line. */
    for (char *p = c->err; *p; p++)
        if (*p == '\n' || *p == '\r')
            *p = ' ';
}

static int join_path(struct charts *c, char *out, const char *name)
{
    int n = snprintf(out, PATH_SIZE, "%s/%s", c->dir, name);
    if (n < 0 || n >= PATH_SIZE) {
        set_error(c, "%s: the folder name is too long", c->dir);
        return TW_ERR_LIMIT;
    }
    return TW_OK;
}

/* ---- reading CSV --------------------------------------------------------------- */

static int csv_open(struct charts *c, struct csv *csv, const char *name)
{
    memset(csv, 0, sizeof(*csv));
    int rc = join_path(c, csv->file, name);
    if (rc)
        return rc;
    csv->f = fopen(csv->file, "r");
    if (!csv->f) {
        set_error(c, "%s: cannot read: %s", csv->file, strerror(errno));
        return TW_ERR_IO;
    }
    return TW_OK;
}

static void csv_close(struct csv *csv)
{
    if (csv->f)
        fclose(csv->f);
    free(csv->line);
    memset(csv, 0, sizeof(*csv));
}

/* Reads the next non-blank line and splits it at commas. Returns 1 for a
 * line, 0 at the end of the file, or a negative error. */
static int csv_next(struct charts *c, struct csv *csv)
{
    for (;;) {
        errno = 0;
        ssize_t n = getline(&csv->line, &csv->line_cap, csv->f);
        if (n < 0) {
            if (ferror(csv->f)) {
                set_error(c, "%s:%lu: read error: %s", csv->file, csv->line_no + 1,
                          strerror(errno ? errno : EIO));
                return TW_ERR_IO;
            }
            return 0;
        }
        csv->line_no++;
        if ((size_t)n != strlen(csv->line)) {
            set_error(c, "%s:%lu: a NUL byte: not a text file", csv->file, csv->line_no);
            return TW_ERR_FORMAT;
        }
        while (n > 0 && (csv->line[n - 1] == '\n' || csv->line[n - 1] == '\r'))
            csv->line[--n] = '\0';
        bool blank = true;
        for (ssize_t k = 0; k < n && blank; k++)
            blank = isspace((unsigned char)csv->line[k]) != 0;
        if (blank)
            continue;
        csv->field_count = 0;
        char *p = csv->line;
        for (;;) {
            if (csv->field_count == MAX_FIELDS) {
                set_error(c, "%s:%lu: more than %d fields", csv->file, csv->line_no, MAX_FIELDS);
                return TW_ERR_LIMIT;
            }
            csv->fields[csv->field_count++] = p;
            char *comma = strchr(p, ',');
            if (!comma)
                break;
            *comma = '\0';
            p = comma + 1;
        }
        return 1;
    }
}

/* Strips the blanks around a field in place. */
static char *trim(char *s)
{
    while (isspace((unsigned char)*s))
        s++;
    size_t n = strlen(s);
    while (n > 0 && isspace((unsigned char)s[n - 1]))
        s[--n] = '\0';
    return s;
}

static int column(struct charts *c, const struct csv *csv, const char *name, bool required)
{
    for (int k = 0; k < csv->field_count; k++)
        if (strcmp(trim(csv->fields[k]), name) == 0)
            return k;
    if (required)
        set_error(c, "%s:%lu: the header has no '%s' column", csv->file, csv->line_no, name);
    return -1;
}

static int check_field_count(struct charts *c, const struct csv *csv, int header_fields)
{
    if (csv->field_count == header_fields)
        return TW_OK;
    set_error(c, "%s:%lu: %d fields where the header has %d", csv->file, csv->line_no,
              csv->field_count, header_fields);
    return TW_ERR_FORMAT;
}

/* A finite number >= 0 spanning the whole field. */
static int number(struct charts *c, const struct csv *csv, int col, const char *name, double *out)
{
    const char *s = trim(csv->fields[col]);
    char *end = NULL;
    errno = 0;
    double v = strtod(s, &end);
    if (*s == '\0' || *end != '\0' || errno == ERANGE || !isfinite(v) || v < 0.0) {
        set_error(c, "%s:%lu: column '%s': '%.40s' is not a non-negative number", csv->file,
                  csv->line_no, name, s);
        return TW_ERR_FORMAT;
    }
    *out = v;
    return TW_OK;
}

/* Names end up in gnuplot strings, data files and file names: keep them to
 * characters that need no quoting anywhere. */
static int name_field(struct charts *c, const struct csv *csv, int col, const char *what,
                      char out[MAX_NAME])
{
    const char *s = trim(csv->fields[col]);
    size_t n = strlen(s);
    bool ok = n > 0 && n < MAX_NAME;
    for (size_t k = 0; k < n && ok; k++)
        ok = isalnum((unsigned char)s[k]) || strchr("+-_.=:/()[]%&*!?~^<>", s[k]);
    if (!ok) {
        set_error(c, "%s:%lu: column '%s': '%.40s' is not a valid name (1 to %d letters, digits "
                  "or + - _ . = : / ( ) [ ] %% & * ! ? ~ ^ < >)",
                  csv->file, csv->line_no, what, s, MAX_NAME - 1);
        return TW_ERR_FORMAT;
    }
    memcpy(out, s, n + 1);
    return TW_OK;
}

/* ---- methods ------------------------------------------------------------------- */

static int colour_of(const char *name)
{
    for (size_t k = 0; k < sizeof(known_methods) / sizeof(known_methods[0]); k++)
        if (strcmp(known_methods[k], name) == 0)
            return (int)k;
    return -1;
}

/* The index of a method, added on first sight. -1 with err set past
 * MAX_METHODS. */
static int method_index(struct charts *c, const char *file, unsigned long line_no,
                        const char *name)
{
    for (int k = 0; k < c->method_count; k++)
        if (strcmp(c->methods[k].name, name) == 0)
            return k;
    if (c->method_count == MAX_METHODS) {
        set_error(c, "%s:%lu: more than %d methods", file, line_no, MAX_METHODS);
        return -1;
    }
    struct method *m = &c->methods[c->method_count];
    memset(m, 0, sizeof(*m));
    snprintf(m->name, sizeof(m->name), "%s", name);
    /* Known methods keep their slot; others take the first slot no method
     * of this run holds. Known names can arrive after unknown ones took
     * their slot, so an unknown name never takes a known method's slot. */
    m->colour = colour_of(name);
    if (m->colour < 0) {
        const int first_free = (int)(sizeof(known_methods) / sizeof(known_methods[0]));
        for (int slot = first_free; slot < MAX_METHODS && m->colour < 0; slot++) {
            bool used = false;
            for (int k = 0; k < c->method_count; k++)
                used |= c->methods[k].colour == slot;
            if (!used)
                m->colour = slot;
        }
        /* More unknown names than free slots: share, rather than fail. */
        if (m->colour < 0)
            m->colour = first_free + c->method_count % (MAX_METHODS - first_free);
    }
    return c->method_count++;
}

/* ---- frames.csv ---------------------------------------------------------------- */

static int open_method_data(struct charts *c, struct method *m)
{
    /* '/' is allowed in names but not in a file name. */
    char safe[MAX_NAME];
    size_t k = 0;
    for (; m->name[k]; k++)
        safe[k] = isalnum((unsigned char)m->name[k]) || strchr("+-_.", m->name[k]) ? m->name[k]
                                                                                    : '_';
    safe[k] = '\0';
    snprintf(m->data_file, sizeof(m->data_file), "chart-data/frames-%s.dat", safe);
    /* Two names may sanitise alike. */
    for (const struct method *o = c->methods; o < m; o++)
        if (strcmp(o->data_file, m->data_file) == 0)
            snprintf(m->data_file, sizeof(m->data_file), "chart-data/frames-%s-%d.dat", safe,
                     (int)(m - c->methods));
    char file[PATH_SIZE];
    int rc = join_path(c, file, m->data_file);
    if (rc)
        return rc;
    m->data = fopen(file, "w");
    if (!m->data) {
        set_error(c, "%s: cannot write: %s", file, strerror(errno));
        return TW_ERR_IO;
    }
    fprintf(m->data, "# method %s: one row per frame, from frames.csv\n"
                     "# frame ms_frame triangles missed_pixels overdraw_triangles\n",
            m->name);
    return TW_OK;
}

/* Streams frames.csv into one data file per method, so memory does not
 * grow with the run, and sums what the summary charts need. */
static int read_frames(struct charts *c)
{
    struct csv csv;
    int rc = csv_open(c, &csv, "frames.csv");
    if (rc)
        return rc;
    rc = csv_next(c, &csv);
    if (rc == 0) {
        set_error(c, "%s: empty file, expected a header line", csv.file);
        rc = TW_ERR_FORMAT;
    }
    if (rc < 0)
        goto out;
    const int header_fields = csv.field_count;
    const int col_method = column(c, &csv, "method", true);
    const int col_ms = column(c, &csv, "ms_frame", true);
    const int col_triangles = column(c, &csv, "triangles", true);
    const int col_frame = column(c, &csv, "frame", false);
    const int col_missed = column(c, &csv, "missed_pixels", false);
    const int col_overdraw = column(c, &csv, "overdraw_triangles", false);
    if (col_method < 0 || col_ms < 0 || col_triangles < 0) {
        rc = TW_ERR_FORMAT;
        goto out;
    }
    c->accuracy_columns = col_missed >= 0 && col_overdraw >= 0;

    uint64_t rows = 0;
    while ((rc = csv_next(c, &csv)) > 0) {
        if ((rc = check_field_count(c, &csv, header_fields)))
            goto out;
        char name[MAX_NAME];
        double ms, triangles, frame = 0.0, missed = 0.0, overdraw = 0.0;
        if ((rc = name_field(c, &csv, col_method, "method", name)) ||
            (rc = number(c, &csv, col_ms, "ms_frame", &ms)) ||
            (rc = number(c, &csv, col_triangles, "triangles", &triangles)) ||
            (col_frame >= 0 && (rc = number(c, &csv, col_frame, "frame", &frame))) ||
            (col_missed >= 0 && (rc = number(c, &csv, col_missed, "missed_pixels", &missed))) ||
            (col_overdraw >= 0 &&
             (rc = number(c, &csv, col_overdraw, "overdraw_triangles", &overdraw))))
            goto out;
        int k = method_index(c, csv.file, csv.line_no, name);
        if (k < 0) {
            rc = TW_ERR_LIMIT;
            goto out;
        }
        struct method *m = &c->methods[k];
        if (!m->data && (rc = open_method_data(c, m)))
            goto out;
        if (m->frames == 0) {
            m->ms_min = m->ms_max = ms;
            m->triangles_min = m->triangles_max = triangles;
        }
        m->ms_min = fmin(m->ms_min, ms);
        m->ms_max = fmax(m->ms_max, ms);
        m->triangles_min = fmin(m->triangles_min, triangles);
        m->triangles_max = fmax(m->triangles_max, triangles);
        m->frames++;
        if (col_frame < 0)
            frame = (double)m->frames;
        m->ms_sum += ms;
        m->triangles_sum += triangles;
        m->missed_total += missed;
        m->overdraw_sum += overdraw;
        fprintf(m->data, "%.10g %.10g %.10g %.10g %.10g\n", frame, ms, triangles, missed,
                overdraw);
        rows++;
    }
    if (rc < 0)
        goto out;
    if (rows == 0) {
        set_error(c, "%s: no frames, only a header line", csv.file);
        rc = TW_ERR_FORMAT;
        goto out;
    }
    rc = TW_OK;
out:
    for (int k = 0; k < c->method_count; k++) {
        struct method *m = &c->methods[k];
        if (m->data && fclose(m->data) != 0 && rc == TW_OK) {
            set_error(c, "%s/%s: write error", c->dir, m->data_file);
            rc = TW_ERR_IO;
        }
        m->data = NULL;
    }
    csv_close(&csv);
    return rc;
}

/* ---- sweep.csv ----------------------------------------------------------------- */

static int compare_sweep_rows(const void *a, const void *b)
{
    const struct sweep_row *x = a, *y = b;
    int d = strcmp(x->param, y->param);
    if (d)
        return d;
    if (x->method_index != y->method_index)
        return x->method_index - y->method_index;
    return (x->x > y->x) - (x->x < y->x);
}

static bool parse_value(const char *s, double *out)
{
    char *end = NULL;
    errno = 0;
    double v = strtod(s, &end);
    if (*s == '\0' || *end != '\0' || errno == ERANGE || !isfinite(v))
        return false;
    *out = v;
    return true;
}

/* By parameter, then value (numbers by value before words in alphabetical
 * order): the order in which ranks are given. */
static int compare_sweep_rows_by_value(const void *a, const void *b)
{
    const struct sweep_row *x = a, *y = b;
    int d = strcmp(x->param, y->param);
    if (d)
        return d;
    double u, v;
    const bool nu = parse_value(x->value, &u), nv = parse_value(y->value, &v);
    if (nu != nv)
        return nu ? -1 : 1;
    if (nu && u != v)
        return (u > v) - (u < v);
    return nu ? 0 : strcmp(x->value, y->value);
}

static size_t group_end(const struct charts *c, size_t start, bool by_method)
{
    size_t end = start;
    while (end < c->sweep_count && strcmp(c->sweep[end].param, c->sweep[start].param) == 0 &&
           (!by_method || c->sweep[end].method_index == c->sweep[start].method_index))
        end++;
    return end;
}

/* x of every sweep row (rows sorted by parameter and value): the value
 * itself, or its rank among the parameter's values when they are not all
 * numbers, or when they include 0 and span decades (0, 1, 4, 16, 64 would
 * bunch up on a linear axis and 0 has no place on a log one). */
static void set_sweep_x(struct charts *c)
{
    for (size_t start = 0; start < c->sweep_count;) {
        const size_t end = group_end(c, start, false);
        bool numeric = true, zero = false;
        double lo = INFINITY, hi = 0.0, v;
        for (size_t k = start; k < end; k++) {
            numeric &= parse_value(c->sweep[k].value, &v);
            if (!numeric)
                break;
            zero |= v == 0.0;
            if (v > 0.0)
                lo = fmin(lo, v);
            hi = fmax(hi, v);
        }
        const bool by_rank = !numeric || (zero && lo < INFINITY && hi / lo >= 50.0);
        double rank = -1.0;
        for (size_t k = start; k < end; k++) {
            struct sweep_row *r = &c->sweep[k];
            r->by_rank = by_rank;
            if (by_rank) {
                if (k == start || strcmp(r->value, r[-1].value) != 0)
                    rank += 1.0;
                r->x = rank;
            } else {
                parse_value(r->value, &r->x);
            }
        }
        start = end;
    }
}

/* A parameter that leaves a method's triangles, missed pixels and overdraw
 * the same at every value changes nothing it draws (T for vfc): its sweep
 * points differ only by timing noise. */
static void mark_unaffected(struct charts *c)
{
    for (size_t start = 0; start < c->sweep_count;) {
        const size_t end = group_end(c, start, true);
        bool same = end - start > 1 && c->sweep[start].mean_triangles >= 0.0;
        for (size_t k = start + 1; k < end && same; k++)
            same = c->sweep[k].mean_triangles == c->sweep[start].mean_triangles &&
                   c->sweep[k].missed_total == c->sweep[start].missed_total &&
                   c->sweep[k].mean_overdraw == c->sweep[start].mean_overdraw;
        for (size_t k = start; k < end; k++)
            c->sweep[k].unaffected = same;
        start = end;
    }
}

/* Reads sweep.csv if there is one. */
static int read_sweep(struct charts *c)
{
    char file[PATH_SIZE];
    int rc = join_path(c, file, "sweep.csv");
    if (rc)
        return rc;
    if (access(file, F_OK) != 0)
        return TW_OK;
    struct csv csv;
    if ((rc = csv_open(c, &csv, "sweep.csv")))
        return rc;
    rc = csv_next(c, &csv);
    if (rc == 0) {
        set_error(c, "%s: empty file, expected a header line", csv.file);
        rc = TW_ERR_FORMAT;
    }
    if (rc < 0)
        goto out;
    const int header_fields = csv.field_count;
    const int col_method = column(c, &csv, "method", true);
    const int col_param = col_method < 0 ? -1 : column(c, &csv, "param", true);
    const int col_value = col_param < 0 ? -1 : column(c, &csv, "value", true);
    const int col_ms = col_value < 0 ? -1 : column(c, &csv, "mean_ms", true);
    const int col_missed = col_ms < 0 ? -1 : column(c, &csv, "missed_pixels_total", true);
    const int col_overdraw =
        col_missed < 0 ? -1 : column(c, &csv, "mean_overdraw_triangles", true);
    if (col_overdraw < 0) {
        rc = TW_ERR_FORMAT;
        goto out;
    }
    const int col_triangles = column(c, &csv, "mean_triangles", false);
    while ((rc = csv_next(c, &csv)) > 0) {
        if ((rc = check_field_count(c, &csv, header_fields)))
            goto out;
        if (c->sweep_count == MAX_SWEEP_ROWS) {
            set_error(c, "%s:%lu: more than %d rows", csv.file, csv.line_no, MAX_SWEEP_ROWS);
            rc = TW_ERR_LIMIT;
            goto out;
        }
        if (c->sweep_count == c->sweep_cap) {
            size_t cap = c->sweep_cap ? c->sweep_cap * 2 : 32;
            struct sweep_row *rows = realloc(c->sweep, cap * sizeof(*rows));
            if (!rows) {
                set_error(c, "%s:%lu: out of memory", csv.file, csv.line_no);
                rc = TW_ERR_NOMEM;
                goto out;
            }
            c->sweep = rows;
            c->sweep_cap = cap;
        }
        struct sweep_row *r = &c->sweep[c->sweep_count];
        memset(r, 0, sizeof(*r));
        if ((rc = name_field(c, &csv, col_method, "method", r->method)) ||
            (rc = name_field(c, &csv, col_param, "param", r->param)) ||
            (rc = name_field(c, &csv, col_value, "value", r->value)) ||
            (rc = number(c, &csv, col_ms, "mean_ms", &r->mean_ms)) ||
            (rc = number(c, &csv, col_missed, "missed_pixels_total", &r->missed_total)) ||
            (rc = number(c, &csv, col_overdraw, "mean_overdraw_triangles", &r->mean_overdraw)) ||
            (col_triangles >= 0 &&
             (rc = number(c, &csv, col_triangles, "mean_triangles", &r->mean_triangles))))
            goto out;
        if (col_triangles < 0)
            r->mean_triangles = -1.0;
        r->method_index = method_index(c, csv.file, csv.line_no, r->method);
        if (r->method_index < 0) {
            rc = TW_ERR_LIMIT;
            goto out;
        }
        c->sweep_count++;
    }
    if (rc < 0)
        goto out;
    if (c->sweep_count > 1)
        qsort(c->sweep, c->sweep_count, sizeof(*c->sweep), compare_sweep_rows_by_value);
    set_sweep_x(c);
    if (c->sweep_count > 1)
        qsort(c->sweep, c->sweep_count, sizeof(*c->sweep), compare_sweep_rows);
    mark_unaffected(c);
    rc = TW_OK;
out:
    csv_close(&csv);
    return rc;
}

/* ---- summary.json: what the run was, for subtitles ------------------------------ */

static void read_summary(struct charts *c)
{
    char file[PATH_SIZE];
    if (join_path(c, file, "summary.json") || access(file, R_OK) != 0)
        return;
    json_object *root = json_object_from_file(file);
    if (!root)
        return;
    const char *keys[] = {"tileset", "path", "size"};
    const char *prefix[] = {"tileset ", "path ", ""};
    size_t len = 0;
    for (int k = 0; k < 3; k++) {
        json_object *v = NULL;
        if (!json_object_object_get_ex(root, keys[k], &v) || !json_object_is_type(v, json_type_string))
            continue;
        int n = snprintf(c->subtitle + len, sizeof(c->subtitle) - len, "%s%s%s",
                         len ? ", " : "", prefix[k], json_object_get_string(v));
        if (n < 0 || (size_t)n >= sizeof(c->subtitle) - len)
            break;
        len += (size_t)n;
    }
    json_object_put(root);
}

/* ---- the gnuplot script -------------------------------------------------------- */

/* A gnuplot double-quoted string: \n inside makes a second title line. */
static void put_quoted(FILE *f, const char *s)
{
    fputc('"', f);
    for (; *s; s++) {
        if (*s == '\n')
            fputs("\\n", f);
        else if (*s == '"' || *s == '\\')
            fprintf(f, "\\%c", *s);
        else if ((unsigned char)*s < 0x20)
            fputc(' ', f);
        else
            fputc(*s, f);
    }
    fputc('"', f);
}

/* The title as a label at a fixed place: gnuplot's title would sit above
 * a key placed at the top, far from its plot. */
static void put_heading(FILE *f, const struct charts *c, const char *title, const char *detail)
{
    char text[1200];
    snprintf(text, sizeof(text), "%s\n%s%s%s", title, c->subtitle, *c->subtitle && *detail ? ", " : "",
             detail);
    fputs("set label 100 ", f);
    put_quoted(f, text);
    fputs(" at screen 0.5, screen 0.955 center font ',13'\n", f);
}

/* Tics at 1, 2, 5 x 10^k inside [lo, hi]: a log axis with labels only at
 * decades reads badly over one or two decades. Over more, decades only. */
static void put_log_tics(FILE *f, char axis, double lo, double hi)
{
    const int steps_per_decade = hi / lo > 1e4 ? 1 : 3;
    const double steps[] = {1.0, 2.0, 5.0};
    fprintf(f, "set %ctics (", axis);
    bool first = true;
    for (double decade = pow(10.0, floor(log10(lo))); decade <= hi; decade *= 10.0) {
        for (int s = 0; s < steps_per_decade; s++) {
            const double v = decade * steps[s];
            if (v < lo || v > hi)
                continue;
            fprintf(f, "%s%.10g", first ? "" : ", ", v);
            first = false;
        }
    }
    fputs(")\n", f);
}

static bool has_frames(const struct method *m) { return m->frames > 0; }

/* The mean per frame of a sum over a method's frames. */
static double per_frame(const struct method *m, double sum) { return sum / (double)m->frames; }

/* Counts read best as plain numbers of a named unit ("800 thousand")
 * rather than "800.0k" or "8e+05". */
struct count_unit {
    double scale;
    const char *name; /* NULL for units of one */
};

static struct count_unit count_unit_for(double max)
{
    if (max >= 1e7)
        return (struct count_unit){1e6, "millions"};
    if (max >= 1e4)
        return (struct count_unit){1e3, "thousands"};
    return (struct count_unit){1.0, NULL};
}

static void human_count(double v, char *out, size_t size)
{
    if (v >= 1e6)
        snprintf(out, size, "%.2fM", v / 1e6);
    else if (v >= 1e4)
        snprintf(out, size, "%.0fk", v / 1e3);
    else
        snprintf(out, size, "%.0f", v);
}

/* A line chart of one column of the per-method frame data. */
static void put_frame_chart(FILE *f, const struct charts *c, const char *output, const char *title,
                            const char *quantity, int column_no, bool triangles)
{
    double lo = INFINITY, hi = 0.0, frame_lo = INFINITY, frame_hi = 0.0;
    uint64_t frames = 0;
    bool same_frames = true;
    for (int k = 0; k < c->method_count; k++) {
        const struct method *m = &c->methods[k];
        if (!has_frames(m))
            continue;
        const double mean = per_frame(m, triangles ? m->triangles_sum : m->ms_sum);
        lo = fmin(lo, mean);
        hi = fmax(hi, mean);
        frame_lo = fmin(frame_lo, triangles ? m->triangles_min : m->ms_min);
        frame_hi = fmax(frame_hi, triangles ? m->triangles_max : m->ms_max);
        same_frames &= frames == 0 || frames == m->frames;
        frames = m->frames;
    }
    char detail[64] = "";
    if (same_frames)
        snprintf(detail, sizeof(detail), "%llu frames per method", (unsigned long long)frames);
    /* Only a spread of more than 10x hides the faster methods on a linear
     * axis; below that a linear axis compares better. */
    const bool log_y = lo > 0.0 && hi / lo > 10.0;
    const struct count_unit unit = triangles ? count_unit_for(hi) : (struct count_unit){1.0, "ms"};
    fprintf(f, "\n# ---- %s ----\nreset\nset terminal @png_term size 1000,600\n", output);
    fprintf(f, "set output '%s'\n", output);
    put_heading(f, c, title, detail);
    /* The key in rows of three between the heading and the plot, where it
     * hides no line. */
    int shown = 0;
    for (int k = 0; k < c->method_count; k++)
        shown += has_frames(&c->methods[k]);
    fprintf(f, "set key at graph 0.5, graph 1.01 bottom center horizontal maxcols 3 Left reverse "
               "samplen 3 width 1\nset tmargin %.1f\n",
            4.5 + (shown + 2) / 3);
    fputs("set xlabel 'frame'\n", f);
    fprintf(f, "set ylabel '%s%s%s%s%s'\n", quantity, unit.name || log_y ? " (" : "",
            unit.name ? unit.name : "", unit.name && log_y ? ", " : "",
            log_y ? "log scale)" : unit.name ? ")" : "");
    fputs("set grid xtics ytics lc rgb '#d8d8d8'\n"
          "set border 3\nset tics nomirror\n"
          "set autoscale xfixmin\nset autoscale xfixmax\nset format y '%g'\n",
          f);
    if (log_y) {
        /* gnuplot would widen a log range to whole decades; a frame of 0
         * (nothing drawn) has no place on it and is left out. */
        if (frame_lo <= 0.0)
            frame_lo = lo;
        const double y_lo = frame_lo / unit.scale / 1.25, y_hi = frame_hi / unit.scale * 1.25;
        fprintf(f, "set logscale y\nset yrange [%.6g:%.6g]\n", y_lo, y_hi);
        put_log_tics(f, 'y', y_lo, y_hi);
    } else {
        fputs("set yrange [0:*]\n", f);
    }
    fputs("plot \\\n", f);
    bool first = true;
    for (int k = 0; k < c->method_count; k++) {
        const struct method *m = &c->methods[k];
        if (!has_frames(m))
            continue;
        char key[128], mean[32];
        if (triangles) {
            human_count(per_frame(m, m->triangles_sum), mean, sizeof(mean));
            snprintf(key, sizeof(key), "%s (mean %s)", m->name, mean);
        } else {
            snprintf(key, sizeof(key), "%s (mean %.1f ms)", m->name, per_frame(m, m->ms_sum));
        }
        fprintf(f, "%s  '%s' using 1:($%d/%g) with lines lt %d title '%s'", first ? "" : ", \\\n",
                m->data_file, column_no, unit.scale, m->colour + 1, key);
        first = false;
    }
    fputs("\n", f);
}

/* ---- point labels that do not overlap ------------------------------------------ */

/* The plot area of one panel of the 1200x600 speed/accuracy chart in
 * gnuplot character cells (offset units, 9 x 17 px with an 11 pt font):
 * rough, but enough to keep labels off each other and off the points. */
#define PANEL_COLS 57.0
#define PANEL_ROWS 26.0

struct point_label {
    double x, y;            /* data coordinates */
    double cx, cy;          /* the point in character cells */
    char text[3 * MAX_NAME + 8];
    bool small;             /* a sweep setting, in a smaller font */
    const char *rgb;        /* the method's colour */
    double dx, dy;          /* chosen offset in character cells */
    int align;              /* -1 right, 0 centre, 1 left of the anchor */
};

struct cell_box {
    double x0, y0, x1, y1;
};

/* The area two boxes share, 0 if they are apart. */
static double overlap_area(const struct cell_box *a, const struct cell_box *b)
{
    const double w = fmin(a->x1, b->x1) - fmax(a->x0, b->x0);
    const double h = fmin(a->y1, b->y1) - fmax(a->y0, b->y0);
    return w > 0.0 && h > 0.0 ? w * h : 0.0;
}

/* Text of 10 pt (8 pt) is about 7 (5.6) px a character, 14 (11) px high. */
static struct cell_box label_box(const struct point_label *l, double dx, double dy, int align)
{
    const double w = (double)strlen(l->text) * (l->small ? 0.62 : 0.78);
    const double h = l->small ? 0.7 : 0.85;
    const double ax = l->cx + dx, ay = l->cy + dy;
    const double x0 = align > 0 ? ax : align < 0 ? ax - w : ax - w / 2.0;
    /* A little padding keeps neighbours from reading as one word. */
    return (struct cell_box){x0 - 0.3, ay - h / 2.0 - 0.05, x0 + w + 0.3, ay + h / 2.0 + 0.05};
}

struct label_spot {
    double dx, dy;
    int align;
};

/* Spots around a point, nearest first so that a label stays next to its
 * point: the eight neighbours, then rings further above and below. */
static int label_spots(struct label_spot *spots, int cap)
{
    static const struct label_spot near[] = {
        {1.3, 0.0, 1}, {1.2, 0.8, 1},   {1.2, -0.8, 1},  {-1.3, 0.0, -1},
        {0.0, 1.2, 0}, {0.0, -1.2, 0},  {-1.2, 0.8, -1}, {-1.2, -0.8, -1},
    };
    int n = 0;
    for (size_t k = 0; k < sizeof(near) / sizeof(near[0]) && n < cap; k++)
        spots[n++] = near[k];
    for (int ring = 1; ring <= 5; ring++) {
        const double dy = 0.8 + 1.0 * ring;
        const struct label_spot more[] = {
            {1.2, dy, 1}, {1.2, -dy, 1}, {-1.2, dy, -1}, {-1.2, -dy, -1},
            {0.0, dy + 0.4, 0}, {0.0, -dy - 0.4, 0},
        };
        for (size_t k = 0; k < sizeof(more) / sizeof(more[0]) && n < cap; k++)
            spots[n++] = more[k];
    }
    return n;
}

/* Greedy: each label takes the first spot around its point that is free of
 * the points, of the labels placed before it and of the fixed obstacles;
 * if none is, the spot that overlaps least. */
static void place_labels(struct point_label *labels, int n, const struct cell_box *obstacles,
                         int obstacle_count)
{
    struct label_spot spots[64];
    const int spot_count = label_spots(spots, 64);
    for (int i = 0; i < n; i++) {
        struct point_label *l = &labels[i];
        int chosen = 0;
        double least = INFINITY;
        for (int s = 0; s < spot_count && least > 0.0; s++) {
            const struct cell_box b = label_box(l, spots[s].dx, spots[s].dy, spots[s].align);
            /* Outside the plot area counts as a large overlap. */
            double overlap = 0.0;
            if (b.x0 < 0.0 || b.x1 > PANEL_COLS + 2.0 || b.y0 < 0.05 || b.y1 > PANEL_ROWS)
                overlap += 100.0;
            for (int k = 0; k < n; k++) {
                /* A dot of 2 (1.3) point sizes is about 14 (9) px wide. */
                const double rx = labels[k].small ? 0.55 : 0.85, ry = labels[k].small ? 0.3 : 0.45;
                const struct cell_box dot = {labels[k].cx - rx, labels[k].cy - ry,
                                             labels[k].cx + rx, labels[k].cy + ry};
                overlap += overlap_area(&b, &dot);
            }
            for (int k = 0; k < i; k++) {
                const struct cell_box other =
                    label_box(&labels[k], labels[k].dx, labels[k].dy, labels[k].align);
                overlap += 4.0 * overlap_area(&b, &other); /* text on text is worst */
            }
            for (int k = 0; k < obstacle_count; k++)
                overlap += overlap_area(&b, &obstacles[k]);
            if (overlap < least) {
                least = overlap;
                chosen = s;
            }
        }
        l->dx = spots[chosen].dx;
        l->dy = spots[chosen].dy;
        l->align = spots[chosen].align;
    }
}

static void put_labels(FILE *f, const struct point_label *labels, int n)
{
    for (int k = 0; k < n; k++) {
        const struct point_label *l = &labels[k];
        fprintf(f, "set label %d '%s' at first %.10g, first %.10g %s offset char %.2f,%.2f "
                   "font ',%d' tc rgb '%s' front\n",
                k + 10, l->text, l->x, l->y, l->align > 0 ? "left" : l->align < 0 ? "right" : "center",
                l->dx, l->dy, l->small ? 8 : 10, l->rgb);
    }
}

/* One panel of the speed/accuracy chart: the methods as filled dots, the
 * sweep settings as open circles joined per method and parameter. */
struct accuracy_panel {
    bool missed;            /* missed pixels, else overdraw triangles */
    bool log_y;             /* a log axis of 1 + value, so that 0 has a place */
    double y_lo, y_hi, x_hi; /* the ranges, in plotted units */
    double y_scale;         /* on a linear axis, value / y_scale is plotted */
    bool key;
};

/* The plotted y of a value, and the same as a gnuplot expression of a
 * data column. */
static double panel_y(const struct accuracy_panel *p, double v)
{
    return p->log_y ? v + 1.0 : v / p->y_scale;
}

static void panel_y_expression(const struct accuracy_panel *p, int column, char *out, size_t size)
{
    if (p->log_y)
        snprintf(out, size, "($%d+1)", column);
    else
        snprintf(out, size, "($%d/%g)", column, p->y_scale);
}

static double panel_cell_y(const struct accuracy_panel *p, double y)
{
    if (p->log_y)
        return (log(y) - log(p->y_lo)) / (log(p->y_hi) - log(p->y_lo)) * PANEL_ROWS;
    return (y - p->y_lo) / (p->y_hi - p->y_lo) * PANEL_ROWS;
}

/* The range of a log axis of 1 + value up to max: room above for labels,
 * and 0 (at 1) a tenth of the height above the axis with room below. */
static void symlog_range(double max, double headroom, double *lo, double *hi)
{
    *hi = fmax(20.0, (max + 1.0) * headroom);
    *lo = pow(*hi, -1.0 / 9.0);
}

/* Tics at 1 + 10^k labelled 10^k, and 0 at 1; the tic for 1 (at 2) would
 * crowd the one for 0 over many decades. */
static void put_symlog_tics(FILE *f, double hi)
{
    fputs("set ytics ('0' 1", f);
    for (double v = hi > 1e4 ? 10.0 : 1.0; v + 1.0 <= hi; v *= 10.0) {
        if (v >= 1e6)
            fprintf(f, ", '%.0fM' %.10g", v / 1e6, v + 1.0);
        else if (v >= 1e4)
            fprintf(f, ", '%.0fk' %.10g", v / 1e3, v + 1.0);
        else
            fprintf(f, ", '%.0f' %.10g", v, v + 1.0);
    }
    fputs(")\n", f);
}

/* Columns of chart-data/methods.dat and chart-data/sweep.dat. */
enum {
    METHODS_MEAN_MS = 2, METHODS_MISSED = 3, METHODS_OVERDRAW = 4,
    SWEEP_X = 4, SWEEP_MEAN_MS = 5, SWEEP_MISSED = 6, SWEEP_OVERDRAW = 7,
};

static int put_accuracy_panel(FILE *f, const struct charts *c, const struct accuracy_panel *p,
                              const struct cell_box *obstacles, int obstacle_count,
                              const char *methods_file, const char *sweep_file)
{
    const int n_max = c->method_count + (int)c->sweep_count;
    struct point_label *labels = calloc((size_t)n_max + 1, sizeof(*labels));
    if (!labels)
        return TW_ERR_NOMEM;
    int n = 0;
    for (int k = 0; k < c->method_count; k++) {
        const struct method *m = &c->methods[k];
        if (!has_frames(m))
            continue;
        struct point_label *l = &labels[n++];
        l->x = per_frame(m, m->ms_sum);
        l->y = panel_y(p, p->missed ? m->missed_total : per_frame(m, m->overdraw_sum));
        snprintf(l->text, sizeof(l->text), "%s", m->name);
        l->rgb = palette[m->colour];
    }
    /* The first point of a method's sweep curve says whose it is; the
     * curve carries the name to the others. */
    for (size_t k = 0; k < c->sweep_count; k++) {
        const struct sweep_row *r = &c->sweep[k];
        if (r->unaffected)
            continue;
        const bool first = k == 0 || r[-1].method_index != r->method_index ||
                           strcmp(r[-1].param, r->param) != 0;
        struct point_label *l = &labels[n++];
        l->x = r->mean_ms;
        l->y = panel_y(p, p->missed ? r->missed_total : r->mean_overdraw);
        l->small = true;
        snprintf(l->text, sizeof(l->text), "%s%s%s=%s", first ? r->method : "", first ? " " : "",
                 r->param, r->value);
        l->rgb = palette[c->methods[r->method_index].colour];
    }
    for (int k = 0; k < n; k++) {
        labels[k].cx = labels[k].x / p->x_hi * PANEL_COLS;
        labels[k].cy = panel_cell_y(p, labels[k].y);
    }
    place_labels(labels, n, obstacles, obstacle_count);
    put_labels(f, labels, n);
    free(labels);

    char y[32];
    panel_y_expression(p, p->missed ? METHODS_MISSED : METHODS_OVERDRAW, y, sizeof(y));
    fputs("plot \\\n", f);
    int row = 0;
    for (int k = 0; k < c->method_count; k++) {
        const struct method *m = &c->methods[k];
        if (!has_frames(m))
            continue;
        fprintf(f, "  '%s' every ::%d::%d using %d:%s with points lt %d pt 7 ps 2 %s%s%s, \\\n",
                methods_file, row, row, METHODS_MEAN_MS, y, m->colour + 1,
                p->key ? "title '" : "notitle", p->key ? m->name : "", p->key ? "'" : "");
        row++;
    }
    panel_y_expression(p, p->missed ? SWEEP_MISSED : SWEEP_OVERDRAW, y, sizeof(y));
    bool any_sweep = false;
    int group = 0;
    for (size_t k = 0; k < c->sweep_count; k = group_end(c, k, true), group++) {
        const struct sweep_row *r = &c->sweep[k];
        if (r->unaffected)
            continue;
        fprintf(f, "  '%s' index %d using %d:%s with linespoints lt %d pt 6 ps 1.3 lw 1 dt 3 "
                   "notitle, \\\n",
                sweep_file, group, SWEEP_MEAN_MS, y, c->methods[r->method_index].colour + 1);
        any_sweep = true;
    }
    /* The plot command needs a last element; it also keys the sweep. */
    if (any_sweep && p->key)
        fputs("  NaN with points lc rgb '#555555' pt 6 ps 1.3 title 'sweep settings'\n", f);
    else
        fputs("  NaN notitle\n", f);
    fputs("unset label\n", f);
    return TW_OK;
}

static int put_speed_accuracy(FILE *f, const struct charts *c, const char *methods_file,
                              const char *sweep_file)
{
    double x_max = 0.0, missed_max = 0.0, overdraw_max = 0.0, overdraw_min = INFINITY;
    bool any_accuracy = false;
    int shown = 0;
    for (int k = 0; k < c->method_count; k++) {
        const struct method *m = &c->methods[k];
        if (!has_frames(m))
            continue;
        shown++;
        const double overdraw = per_frame(m, m->overdraw_sum);
        x_max = fmax(x_max, per_frame(m, m->ms_sum));
        missed_max = fmax(missed_max, m->missed_total);
        overdraw_max = fmax(overdraw_max, overdraw);
        if (overdraw > 0.0)
            overdraw_min = fmin(overdraw_min, overdraw);
        any_accuracy |= m->missed_total > 0.0 || m->overdraw_sum > 0.0;
    }
    bool any_sweep = false;
    for (size_t k = 0; k < c->sweep_count; k++) {
        const struct sweep_row *r = &c->sweep[k];
        if (r->unaffected)
            continue;
        any_sweep = true;
        x_max = fmax(x_max, r->mean_ms);
        missed_max = fmax(missed_max, r->missed_total);
        overdraw_max = fmax(overdraw_max, r->mean_overdraw);
        if (r->mean_overdraw > 0.0)
            overdraw_min = fmin(overdraw_min, r->mean_overdraw);
        any_accuracy |= r->missed_total > 0.0 || r->mean_overdraw > 0.0;
    }
    /* Headroom to the right for the point labels. */
    const double x_hi = x_max > 0.0 ? x_max * 1.25 : 1.0;

    fputs("\n# ---- chart-speed-accuracy.png ----\nreset\n"
          "set terminal @png_term size 1200,600\n"
          "set output 'chart-speed-accuracy.png'\n",
          f);
    char text[1024];
    snprintf(text, sizeof(text),
             "Speed against accuracy: one point per method, lower left is better%s%s",
             *c->subtitle ? "\n" : "", c->subtitle);
    fputs("set multiplot layout 1,2 title ", f);
    put_quoted(f, text);
    fputs(" font ',13'\n", f);
    fputs("set grid xtics ytics lc rgb '#d8d8d8'\nset border 3\nset tics nomirror\n"
          "set key top right Left reverse samplen 1 spacing 1.1 box lc rgb '#bbbbbb' opaque\n",
          f);
    fprintf(f, "set xlabel 'mean frame time (ms)'\nset xrange [0:%.6g]\n", x_hi);
    /* Without --verify every accuracy column is 0: say so rather than
     * show every method as perfect. */
    const bool unmeasured = !c->accuracy_columns || !any_accuracy;

    /* Left panel: missed pixels, 0 expected of conservative methods. */
    struct accuracy_panel missed = {.missed = true, .log_y = true, .x_hi = x_hi, .y_scale = 1.0,
                                    .key = true};
    symlog_range(missed_max, 8.0, &missed.y_lo, &missed.y_hi);
    fputs("set title 'Missed pixels (visible errors)' font ',12'\n"
          "set ylabel 'missed pixels, total over the run (log scale of 1 + value)'\n"
          "set logscale y\n",
          f);
    fprintf(f, "set yrange [%.6g:%.6g]\n", missed.y_lo, missed.y_hi);
    put_symlog_tics(f, missed.y_hi);
    const double zero_row = panel_cell_y(&missed, 1.0);
    fputs("set arrow 1 from graph 0, first 1 to graph 1, first 1 nohead lc rgb '#9a9a9a' dt 2 back\n"
          "set label 1 'no pixel missed (conservative)' at graph 0.99, first 1 right "
          "offset 0,-1 tc rgb '#6a6a6a' font ',9'\n",
          f);
    if (unmeasured)
        fputs("set label 2 \"no missed pixels and no overdraw recorded:\\nwas bench run with --verify?\" "
              "at graph 0.5, graph 0.6 center tc rgb '#b00000' font ',12'\n",
              f);
    /* The key (top right), the conservative line's label, the warning, the
     * conservative line itself (text across a dashed line reads badly). */
    const struct cell_box missed_obstacles[] = {
        {PANEL_COLS - 19.0, PANEL_ROWS - 1.2 * (shown + (any_sweep ? 2 : 1)), PANEL_COLS + 2.0,
         PANEL_ROWS + 1.0},
        {PANEL_COLS - 27.0, zero_row - 1.6, PANEL_COLS + 2.0, zero_row - 0.4},
        {PANEL_COLS / 2.0 - 16.0, PANEL_ROWS * 0.6 - 1.5, PANEL_COLS / 2.0 + 16.0,
         unmeasured ? PANEL_ROWS * 0.6 + 1.5 : PANEL_ROWS * 0.6 - 1.5},
        {0.0, zero_row - 0.1, PANEL_COLS + 2.0, zero_row + 0.1},
    };
    int rc = put_accuracy_panel(f, c, &missed, missed_obstacles, 4, methods_file, sweep_file);
    if (rc)
        return rc;

    /* Right panel: overdraw, on a log axis too when vfc's dwarfs the rest. */
    struct accuracy_panel overdraw = {.missed = false, .x_hi = x_hi, .y_scale = 1.0};
    overdraw.log_y = overdraw_min < INFINITY && overdraw_max / overdraw_min > 10.0;
    const struct count_unit unit = count_unit_for(overdraw_max);
    fputs("unset arrow 1\nunset key\n"
          "set title 'Overdraw (wasted work)' font ',12'\n",
          f);
    if (overdraw.log_y) {
        symlog_range(overdraw_max, 4.0, &overdraw.y_lo, &overdraw.y_hi);
        fputs("set ylabel 'overdraw triangles per frame, mean (log scale of 1 + value)'\n", f);
        fprintf(f, "set yrange [%.6g:%.6g]\n", overdraw.y_lo, overdraw.y_hi);
        put_symlog_tics(f, overdraw.y_hi);
    } else {
        overdraw.y_scale = unit.scale;
        overdraw.y_lo = 0.0;
        overdraw.y_hi = overdraw_max > 0.0 ? overdraw_max / unit.scale * 1.15 : 1.0;
        fputs("unset logscale y\n", f);
        fprintf(f, "set ylabel 'overdraw triangles per frame, mean%s%s%s'\n",
                unit.name ? " (" : "", unit.name ? unit.name : "", unit.name ? ")" : "");
        fputs("set ytics autofreq\nset format y '%g'\n", f);
        fprintf(f, "set yrange [0:%.6g]\n", overdraw.y_hi);
    }
    fputs("set label 1 'triangles drawn in clusters with no visible pixel' at graph 0.99, graph 0.98 "
          "right tc rgb '#6a6a6a' font ',9'\n",
          f);
    if (unmeasured)
        fputs("set label 2 'accuracy not measured?' at graph 0.5, graph 0.6 center tc rgb '#b00000' "
              "font ',12'\n",
              f);
    const struct cell_box overdraw_obstacles[] = {
        {PANEL_COLS - 36.0, PANEL_ROWS - 1.2, PANEL_COLS + 2.0, PANEL_ROWS + 1.0},
        {PANEL_COLS / 2.0 - 12.0, PANEL_ROWS * 0.6 - 0.8, PANEL_COLS / 2.0 + 12.0,
         unmeasured ? PANEL_ROWS * 0.6 + 0.8 : PANEL_ROWS * 0.6 - 0.8},
    };
    rc = put_accuracy_panel(f, c, &overdraw, overdraw_obstacles, 2, methods_file, sweep_file);
    if (rc)
        return rc;
    fputs("unset multiplot\n", f);
    return TW_OK;
}

/* One panel per swept parameter, one line per method. */
static void put_sweep_chart(FILE *f, const struct charts *c, const char *sweep_file)
{
    int params = 0;
    for (size_t k = 0; k < c->sweep_count; k = group_end(c, k, false))
        params++;
    const int cols = params < 2 ? 1 : 2;
    const int rows_of_panels = (params + cols - 1) / cols;
    fprintf(f, "\n# ---- chart-sweep.png ----\nreset\nset terminal @png_term size 1000,%d\n",
            rows_of_panels > 1 ? 450 * rows_of_panels : 600);
    fputs("set output 'chart-sweep.png'\n", f);
    char text[1024];
    snprintf(text, sizeof(text), "Mean frame time against each swept parameter (lower is better)%s%s",
             *c->subtitle ? "\n" : "", c->subtitle);
    fprintf(f, "set multiplot layout %d,%d title ", rows_of_panels, cols);
    put_quoted(f, text);
    fputs(" font ',13'\n", f);
    fputs("set grid xtics ytics lc rgb '#d8d8d8'\nset border 3\nset tics nomirror\n"
          /* In a multiplot, a key below the panel lands on the x label. */
          "set key outside right top vertical Left reverse samplen 2\n",
          f);
    int group = 0;
    for (size_t k = 0; k < c->sweep_count;) {
        const size_t end = group_end(c, k, false);
        const char *param = c->sweep[k].param;
        const bool by_rank = c->sweep[k].by_rank;
        double lo = INFINITY, hi = -INFINITY, ms_lo = INFINITY, ms_hi = 0.0;
        bool any_unaffected = false;
        for (size_t j = k; j < end; j++) {
            lo = fmin(lo, c->sweep[j].x);
            hi = fmax(hi, c->sweep[j].x);
            ms_lo = fmin(ms_lo, c->sweep[j].mean_ms);
            ms_hi = fmax(ms_hi, c->sweep[j].mean_ms);
            any_unaffected |= c->sweep[j].unaffected;
        }
        /* Sizes are often swept by doubling: a log axis spaces them
         * evenly. Times, like the frame chart, on a log axis past 10x. */
        const bool log_x = !by_rank && lo > 0.0 && hi / lo >= 50.0;
        const bool log_y = ms_lo > 0.0 && ms_hi / ms_lo > 10.0;
        fprintf(f, "set title 'parameter %s' font ',12'\nset xlabel '%s%s'\n", param, param,
                by_rank ? " (evenly spaced)" : "");
        fputs(log_x ? "set logscale x 2\n" : "unset logscale x\n", f);
        /* A margin so that the end points are not on the frame. */
        if (log_x)
            fprintf(f, "set xrange [%.10g:%.10g]\n", lo / 1.25, hi * 1.25);
        else if (hi > lo)
            fprintf(f, "set xrange [%.10g:%.10g]\n", lo - (hi - lo) * 0.08, hi + (hi - lo) * 0.08);
        else
            fprintf(f, "set xrange [%.10g:%.10g]\n", lo - 1.0, hi + 1.0);
        fputs(by_rank ? "unset xtics\nset xtics nomirror\n" : "set xtics autofreq\n", f);
        if (log_y) {
            fprintf(f, "set logscale y\nset yrange [%.6g:%.6g]\n", ms_lo / 1.25, ms_hi * 1.25);
            fputs("set ylabel 'mean frame time (ms, log scale)'\n", f);
            put_log_tics(f, 'y', ms_lo / 1.25, ms_hi * 1.25);
        } else {
            fputs("unset logscale y\nset yrange [0:*]\nset ytics autofreq\n"
                  "set ylabel 'mean frame time (ms)'\n",
                  f);
        }
        if (any_unaffected)
            fprintf(f, "set label 1 'unaffected: %s changes nothing the method draws' at graph 0.01, "
                       "graph 1.02 left font ',9' tc rgb '#6a6a6a'\n",
                    param);
        else
            fputs("unset label 1\n", f);
        fputs("plot \\\n", f);
        bool first = true;
        for (; k < end; k = group_end(c, k, true), group++) {
            const struct sweep_row *r = &c->sweep[k];
            const struct method *m = &c->methods[r->method_index];
            fprintf(f, "%s  '%s' index %d using %d:%d%s with linespoints lt %d pt 7 ps 1.3%s "
                       "title '%s%s'",
                    first ? "" : ", \\\n", sweep_file, group, SWEEP_X, SWEEP_MEAN_MS,
                    by_rank ? ":xtic(3)" : "", m->colour + 1, r->unaffected ? " lw 1" : "",
                    m->name, r->unaffected ? " (unaffected)" : "");
            first = false;
        }
        fputs("\n", f);
    }
    fputs("unset multiplot\n", f);
}

static int write_data(struct charts *c, const char *name, bool (*write)(FILE *, const struct charts *))
{
    char file[PATH_SIZE];
    int rc = join_path(c, file, name);
    if (rc)
        return rc;
    FILE *f = fopen(file, "w");
    if (!f) {
        set_error(c, "%s: cannot write: %s", file, strerror(errno));
        return TW_ERR_IO;
    }
    bool ok = write(f, c);
    if (fclose(f) != 0 || !ok) {
        set_error(c, "%s: write error", file);
        return TW_ERR_IO;
    }
    return TW_OK;
}

static bool write_methods(FILE *f, const struct charts *c)
{
    fputs("# one row per method, from frames.csv\n"
          "# method mean_ms missed_pixels_total mean_overdraw_triangles frames mean_triangles\n",
          f);
    for (int k = 0; k < c->method_count; k++) {
        const struct method *m = &c->methods[k];
        if (!has_frames(m))
            continue;
        fprintf(f, "\"%s\" %.6f %.10g %.6f %llu %.3f\n", m->name, per_frame(m, m->ms_sum),
                m->missed_total, per_frame(m, m->overdraw_sum), (unsigned long long)m->frames,
                per_frame(m, m->triangles_sum));
    }
    return !ferror(f);
}

static bool write_sweep(FILE *f, const struct charts *c)
{
    fputs("# from sweep.csv: one block (gnuplot index) per parameter and method, by value;\n"
          "# x is the value, or its rank for a parameter plotted evenly spaced\n"
          "# method param value x mean_ms missed_pixels_total mean_overdraw_triangles label\n",
          f);
    for (size_t k = 0; k < c->sweep_count; k++) {
        const struct sweep_row *r = &c->sweep[k];
        if (k > 0 && (strcmp(r->param, r[-1].param) != 0 || r->method_index != r[-1].method_index))
            fputs("\n\n", f);
        fprintf(f, "\"%s\" \"%s\" \"%s\" %.10g %.6f %.10g %.6f \"%s %s=%s\"\n", r->method, r->param,
                r->value, r->x, r->mean_ms, r->missed_total, r->mean_overdraw, r->method, r->param,
                r->value);
    }
    return !ferror(f);
}

static bool write_script(FILE *f, const struct charts *c)
{
    fprintf(f, "# The charts of a tileworld bench run, written by tileworld (runtime/charts.c)\n"
               "# from frames.csv%s. Edit and re-run here with: gnuplot charts.gp\n"
               "# Data: chart-data/ (see the header line of each file).\n\n",
            c->sweep_count ? " and sweep.csv" : "");
    fputs("# pngcairo draws antialiased text; the gd png terminal is the fallback.\n"
          "# noenhanced: method names such as tilequery+chc are printed as they are.\n"
          "if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) {\n"
          "    png_term = \"pngcairo noenhanced font 'DejaVu Sans,11' linewidth 1.3\"\n"
          "} else {\n"
          "    png_term = \"png noenhanced\"\n"
          "}\n\n"
          "# One colour per method, the same in every chart: linetypes, unlike\n"
          "# line styles, survive the reset before each chart.\n",
          f);
    for (int k = 0; k < c->method_count; k++) {
        const struct method *m = &c->methods[k];
        fprintf(f, "set linetype %d lc rgb '%s' lw 2 dt %d pt 7  # %s\n", m->colour + 1,
                palette[m->colour], strcmp(m->name, "oracle") == 0 ? 2 : 1, m->name);
    }
    put_frame_chart(f, c, "chart-frame-time.png", "Frame time per frame (lower is better)",
                    "frame time", 2, false);
    put_frame_chart(f, c, "chart-triangles.png", "Triangles drawn per frame (lower is better)",
                    "triangles drawn per frame", 3, true);
    if (put_speed_accuracy(f, c, "chart-data/methods.dat", "chart-data/sweep.dat"))
        return false;
    if (c->sweep_count)
        put_sweep_chart(f, c, "chart-data/sweep.dat");
    return !ferror(f);
}

/* ---- running gnuplot ------------------------------------------------------------ */

/* Looks gnuplot up in PATH in the parent, so the child only needs the
 * async-signal-safe execv() (the caller may have threads). */
static bool find_program(const char *name, char *out, size_t size)
{
    const char *path = getenv("PATH");
    if (!path || !*path)
        path = "/usr/local/bin:/usr/bin:/bin";
    for (const char *p = path;;) {
        const char *colon = strchr(p, ':');
        const size_t n = colon ? (size_t)(colon - p) : strlen(p);
        int len = n ? snprintf(out, size, "%.*s/%s", (int)n, p, name)
                    : snprintf(out, size, "./%s", name);
        struct stat st;
        if (len > 0 && (size_t)len < size && stat(out, &st) == 0 && S_ISREG(st.st_mode) &&
            access(out, X_OK) == 0)
            return true;
        if (!colon)
            return false;
        p = colon + 1;
    }
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

/* The most telling line of gnuplot's stderr: its last non-blank one (the
 * error with its script line comes last). */
static void last_line(const char *text, char *out, size_t size)
{
    const char *best = NULL;
    size_t best_len = 0;
    for (const char *p = text; *p;) {
        const char *end = strchr(p, '\n');
        const size_t n = end ? (size_t)(end - p) : strlen(p);
        bool blank = true;
        for (size_t k = 0; k < n && blank; k++)
            blank = isspace((unsigned char)p[k]) || p[k] == '^';
        if (!blank) {
            best = p;
            best_len = n;
        }
        p += n + (end != NULL);
    }
    snprintf(out, size, "%.*s", best ? (int)best_len : 0, best ? best : "");
}

static int run_gnuplot(struct charts *c, const char *gnuplot)
{
    int pipe_fds[2];
    if (pipe(pipe_fds) != 0) {
        set_error(c, "%s: cannot run gnuplot: pipe: %s", c->dir, strerror(errno));
        return TW_ERR_IO;
    }
    /* Another thread's child must not inherit the write end, or EOF would
     * wait for that child. */
    fcntl(pipe_fds[0], F_SETFD, FD_CLOEXEC);
    fcntl(pipe_fds[1], F_SETFD, FD_CLOEXEC);
    const int dev_null = open("/dev/null", O_RDWR | O_CLOEXEC);
    const pid_t pid = dev_null < 0 ? -1 : fork();
    if (pid == 0) {
        /* The child: async-signal-safe calls only. */
        dup2(dev_null, STDIN_FILENO);
        dup2(dev_null, STDOUT_FILENO);
        dup2(pipe_fds[1], STDERR_FILENO);
        if (chdir(c->dir) != 0)
            _exit(126);
        char *const argv[] = {"gnuplot", "charts.gp", NULL};
        execv(gnuplot, argv);
        _exit(127);
    }
    const int fork_errno = errno;
    close(pipe_fds[1]);
    if (dev_null >= 0)
        close(dev_null);
    if (pid < 0) {
        close(pipe_fds[0]);
        set_error(c, "%s: cannot run gnuplot: %s", c->dir, strerror(fork_errno));
        return TW_ERR_IO;
    }

    char output[4096];
    size_t output_len = 0;
    const double deadline = now_s() + GNUPLOT_TIMEOUT_S;
    bool open_pipe = true, reaped = false, timed_out = false;
    int status = 0, wait_errno = 0;
    while (open_pipe || !reaped) {
        if (now_s() >= deadline) {
            timed_out = true;
            break;
        }
        if (!reaped) {
            const pid_t done = waitpid(pid, &status, WNOHANG);
            if (done == pid) {
                reaped = true;
            } else if (done < 0 && errno != EINTR) {
                wait_errno = errno;
                reaped = true;
                status = -1;
            }
        }
        if (!open_pipe) {
            const struct timespec pause = {0, 10 * 1000 * 1000};
            nanosleep(&pause, NULL);
            continue;
        }
        /* Once gnuplot has exited only what is already in the pipe is read:
         * a process it left behind holding the pipe must not hold us. */
        struct pollfd pfd = {pipe_fds[0], POLLIN, 0};
        const int ready = poll(&pfd, 1, reaped ? 0 : 50);
        if (ready < 0) {
            open_pipe = errno == EINTR;
            continue;
        }
        if (ready == 0) {
            open_pipe = !reaped;
            continue;
        }
        char buf[1024];
        const ssize_t n = read(pipe_fds[0], buf, sizeof(buf));
        if (n > 0) {
            /* Keep the tail: the error is at the end. */
            const size_t take = (size_t)n;
            if (output_len + take > sizeof(output) - 1) {
                const size_t drop = output_len + take - (sizeof(output) - 1);
                memmove(output, output + drop, output_len - drop);
                output_len -= drop;
            }
            memcpy(output + output_len, buf, take);
            output_len += take;
        } else if (n == 0 || errno != EINTR) {
            open_pipe = false;
        }
    }
    close(pipe_fds[0]);
    if (timed_out) {
        if (!reaped) {
            kill(pid, SIGKILL);
            waitpid(pid, &status, 0);
        }
        set_error(c, "%s/charts.gp: gnuplot did not finish within %d s and was stopped", c->dir,
                  GNUPLOT_TIMEOUT_S);
        return TW_ERR_IO;
    }
    output[output_len] = '\0';
    char reason[1024];
    last_line(output, reason, sizeof(reason));
    if (status == -1) {
        set_error(c, "%s/charts.gp: lost track of gnuplot: %s", c->dir, strerror(wait_errno));
        return TW_ERR_IO;
    }
    if (WIFSIGNALED(status)) {
        set_error(c, "%s/charts.gp: gnuplot was killed by signal %d%s%s", c->dir, WTERMSIG(status),
                  *reason ? ": " : "", reason);
        return TW_ERR_IO;
    }
    const int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    if (code == 126) {
        set_error(c, "%s: gnuplot cannot enter the folder", c->dir);
        return TW_ERR_IO;
    }
    if (code == 127) {
        set_error(c, "%s: cannot start %s", c->dir, gnuplot);
        return TW_ERR_IO;
    }
    if (code != 0) {
        set_error(c, "%s/charts.gp: gnuplot failed (exit status %d): %s", c->dir, code,
                  *reason ? reason : "no message");
        return TW_ERR_IO;
    }
    return TW_OK;
}

/* ---- the entry point ------------------------------------------------------------- */

int tw_charts_write(const char *dir, char *err, size_t err_size)
{
    if (err && err_size)
        err[0] = '\0';
    if (!dir || !*dir) {
        if (err && err_size)
            snprintf(err, err_size, "charts: no folder given");
        return TW_ERR_INVALID;
    }
    struct charts *c = calloc(1, sizeof(*c));
    if (!c) {
        if (err && err_size)
            snprintf(err, err_size, "%s: out of memory for the charts", dir);
        return TW_ERR_NOMEM;
    }
    c->dir = dir;
    c->err = err;
    c->err_size = err ? err_size : 0;

    char file[PATH_SIZE];
    int rc = join_path(c, file, "chart-data");
    if (rc)
        goto out;
    if (mkdir(file, 0777) != 0 && errno != EEXIST) {
        set_error(c, "%s: cannot create: %s", file, strerror(errno));
        rc = TW_ERR_IO;
        goto out;
    }
    if ((rc = read_frames(c)) || (rc = read_sweep(c)))
        goto out;
    read_summary(c);
    if ((rc = write_data(c, "chart-data/methods.dat", write_methods)) ||
        (c->sweep_count && (rc = write_data(c, "chart-data/sweep.dat", write_sweep))) ||
        (rc = write_data(c, "charts.gp", write_script)))
        goto out;
    /* A sweep chart left from an earlier run would pass for this one's. */
    if (!c->sweep_count && !join_path(c, file, "chart-sweep.png"))
        unlink(file);

    char gnuplot[PATH_SIZE];
    if (!find_program("gnuplot", gnuplot, sizeof(gnuplot))) {
        set_error(c, "%s: gnuplot is not installed (not found in PATH), so no charts were drawn; "
                  "charts.gp is written: install gnuplot and run it there",
                  dir);
        rc = TW_ERR_IO;
        goto out;
    }
    rc = run_gnuplot(c, gnuplot);
out:
    free(c->sweep);
    free(c);
    return rc;
}
