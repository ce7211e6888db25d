/* frames.csv, the per-method chart data, summary.json and summary.md (report.h). */
#include "tools/tileworld/report.h"

#include <errno.h>
#include <json-c/json.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

int tw_report_make_dirs(const char *dir)
{
    char buf[1024];
    if (strlen(dir) >= sizeof(buf))
        return ENAMETOOLONG;
    strcpy(buf, dir);
    for (char *p = buf + 1; *p; p++) {
        if (*p != '/')
            continue;
        *p = '\0';
        if (mkdir(buf, 0777) != 0 && errno != EEXIST)
            return errno;
        *p = '/';
    }
    if (mkdir(buf, 0777) != 0 && errno != EEXIST)
        return errno;
    struct stat st;
    if (stat(buf, &st) != 0)
        return errno;
    if (!S_ISDIR(st.st_mode))
        return ENOTDIR;
    return 0;
}

static const char *const csv_header =
    "frame,method,ms_frame,ms_cull,ms_wait,triangles,clusters,draws,queries,tiles_queried,"
    "tiles_visible,tiles_new,tiles_cached,cache_bytes,predict_fail,missed_pixels,"
    "missed_clusters,overdraw_triangles,cpu_ms,depth_errors,tiles_pending,loads_requested,"
    "loads_done,evictions,bytes_cpu,bytes_gpu,bytes_state,bytes_needed,over_budget,ms_upload,"
    "blocking_reads,queries_skipped,hzb_boxes,ms_hzb_build,ms_hzb_read,bytes_loading,"
    "tiles_loading,set_cpu_ms,set_ms,set_triangles,set_draws,overdraw_box_triangles,gpu_ms,"
    "gpu_ms_id\n";

/* A row of frames.csv as the row of a gnuplot data file: blank-separated,
 * without the method (its file says it). */
static void csv_to_data(const char *csv, char *out, size_t size)
{
    size_t n = 0;
    int field = 0;
    for (const char *c = csv; *c && n + 1 < size; c++) {
        if (*c == ',')
            field++;
        if (field == 1)
            continue;
        out[n++] = *c == ',' ? ' ' : *c;
    }
    out[n] = '\0';
}

int tw_report_open(struct tw_report *r, const char *dir, bool chart_data, char *err,
                   size_t err_size)
{
    const struct tw_report_about about = r->about;
    memset(r, 0, sizeof(*r));
    r->about = about;
    r->chart_data = chart_data;
    int e = tw_report_make_dirs(dir);
    if (e) {
        snprintf(err, err_size, "%s: cannot create the output folder: %s", dir, strerror(e));
        return TW_ERR_INVALID;
    }
    snprintf(r->dir, sizeof(r->dir), "%s", dir);
    char file[1100];
    if (chart_data) {
        snprintf(file, sizeof(file), "%s/" TW_REPORT_CHART_DATA, dir);
        if (mkdir(file, 0777) != 0 && errno != EEXIST) {
            snprintf(err, err_size, "%s: cannot create: %s", file, strerror(errno));
            return TW_ERR_IO;
        }
    }
    snprintf(file, sizeof(file), "%s/frames.csv", dir);
    int rc = tw_outfile_open(&r->frames_csv, file, err, err_size);
    if (rc)
        return rc;
    r->open = true;
    if (!tw_outfile_printf(&r->frames_csv, "%s", csv_header))
        return tw_outfile_report(&r->frames_csv, err, err_size);
    return TW_OK;
}

/* The chart data file of a method, opened with its header on first use. */
static struct tw_outfile *chart_frames(struct tw_report *r, enum tw_method m, char *err,
                                       size_t err_size)
{
    struct tw_outfile *o = &r->chart_frames[m];
    if (o->f)
        return o;
    char file[1100], header[1024];
    snprintf(file, sizeof(file), "%s/" TW_REPORT_CHART_DATA "/frames-%s.dat", r->dir,
             tw_method_name(m));
    if (tw_outfile_open(o, file, err, err_size))
        return NULL;
    csv_to_data(csv_header, header, sizeof(header));
    tw_outfile_printf(o, "# %s: one row per frame, columns as in frames.csv\n%s",
                      tw_method_name(m), header);
    return o;
}

int tw_report_add(struct tw_report *r, const struct tw_frame_stats *st,
                  const struct tw_report_set *set, char *err, size_t err_size)
{
    static const struct tw_report_set none = {0};
    const struct tw_report_set *sv = set ? set : &none;
    char row[1024];
    snprintf(row, sizeof(row),
             "%llu,%s,%.3f,%.3f,%.3f,%llu,%u,%u,%u,%u,%u,%u,%u,%llu,%u,%llu,%u,%llu,%.3f,%llu,"
             "%u,%u,%u,%u,%llu,%llu,%llu,%llu,%d,%.3f,"
             "%u,%u,%u,%.3f,%.3f,%llu,%u,%.3f,%.3f,%llu,%u,%llu,%.3f,%.3f\n",
             (unsigned long long)st->frame, tw_method_name(st->method), st->ms_frame, st->ms_cull,
             st->ms_wait, (unsigned long long)st->triangles, st->clusters, st->draws, st->queries,
             st->tiles_queried, st->tiles_visible, st->tiles_new, st->tiles_cached,
             (unsigned long long)st->cache_bytes, st->predict_fail,
             (unsigned long long)st->missed_pixels, st->missed_clusters,
             (unsigned long long)st->overdraw_triangles, st->cpu_ms,
             (unsigned long long)st->depth_errors, st->tiles_pending, st->loads_requested,
             st->loads_done, st->evictions, (unsigned long long)st->bytes_cpu,
             (unsigned long long)st->bytes_gpu, (unsigned long long)st->bytes_state,
             (unsigned long long)st->bytes_needed, st->over_budget ? 1 : 0, st->ms_upload,
             st->blocking_reads, st->queries_skipped, st->hzb_boxes, st->ms_hzb_build,
             st->ms_hzb_read, (unsigned long long)st->bytes_loading, st->tiles_loading,
             sv->cpu_ms, sv->ms, (unsigned long long)sv->triangles, sv->draws,
             (unsigned long long)st->overdraw_box_triangles, st->gpu_ms, st->gpu_ms_id);
    if (!tw_outfile_printf(&r->frames_csv, "%s", row))
        return tw_outfile_report(&r->frames_csv, err, err_size);
    if (r->chart_data) {
        struct tw_outfile *o = chart_frames(r, st->method, err, err_size);
        if (!o)
            return TW_ERR_IO;
        char data[1024];
        csv_to_data(row, data, sizeof(data));
        if (!tw_outfile_printf(o, "%s", data))
            return tw_outfile_report(o, err, err_size);
    }
    struct tw_method_summary *m = &r->methods[st->method];
    if (m->frames == m->cap) {
        uint32_t cap = m->cap ? m->cap * 2 : 256;
        double *ms = realloc(m->ms, sizeof(*ms) * cap);
        if (ms)
            m->ms = ms;
        double *cpu = ms ? realloc(m->cpu_ms, sizeof(*cpu) * cap) : NULL;
        if (cpu)
            m->cpu_ms = cpu;
        double *gpu = cpu ? realloc(m->gpu_ms, sizeof(*gpu) * cap) : NULL;
        if (!gpu) {
            snprintf(err, err_size, "out of memory");
            return TW_ERR_NOMEM;
        }
        m->gpu_ms = gpu;
        m->cap = cap;
    }
    m->used = true;
    if (st->gpu_ms >= 0.0)
        m->gpu_ms[m->gpu_frames++] = st->gpu_ms;
    m->cpu_ms[m->frames] = st->cpu_ms;
    m->ms[m->frames++] = st->ms_frame;
    m->triangles += (double)st->triangles;
    m->queries += st->queries;
    m->missed_pixels_total += st->missed_pixels;
    m->frames_with_missed_pixels += st->missed_pixels > 0;
    m->missed_clusters_total += st->missed_clusters;
    m->depth_errors_total += st->depth_errors;
    m->frames_with_depth_errors += st->depth_errors > 0;
    m->tiles_new_total += st->tiles_new;
    if (st->cache_bytes > m->peak_cache_bytes)
        m->peak_cache_bytes = st->cache_bytes;
    m->predict_fail += st->predict_fail;
    m->tiles_queried += st->tiles_queried;
    m->tiles_visible += st->tiles_visible;
    if (st->tiles_visible > m->max_tiles_visible)
        m->max_tiles_visible = st->tiles_visible;
    m->ms_wait += st->ms_wait;
    m->overdraw_triangles += (double)st->overdraw_triangles;
    m->overdraw_box_triangles += (double)st->overdraw_box_triangles;
    if (st->ms_frame > m->ms_max)
        m->ms_max = st->ms_frame;
    if (set) {
        m->set_frames++;
        m->set_cpu_ms += set->cpu_ms;
        m->set_ms += set->ms;
        m->set_triangles += (double)set->triangles;
        m->set_draws += set->draws;
    }
    return TW_OK;
}

int tw_report_write_json(const char *file, struct json_object *root, int flags, char *err,
                         size_t err_size)
{
    const char *text = json_object_to_json_string_ext(root, flags);
    if (!text) {
        snprintf(err, err_size, "%s: out of memory", file);
        return TW_ERR_NOMEM;
    }
    return tw_outfile_write_all(file, text, strlen(text), err, err_size);
}

static int compare_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

double tw_report_percentile(double *values, uint32_t n, double p)
{
    if (n == 0)
        return 0.0;
    qsort(values, n, sizeof(*values), compare_double);
    double rank = ceil(p / 100.0 * n);
    uint32_t k = rank < 1.0 ? 0 : (uint32_t)rank - 1;
    if (k >= n)
        k = n - 1;
    return values[k];
}

struct row {
    const char *name;
    enum tw_method method;
    double mean, median, p95, p99, triangles, queries;
    double cpu_mean, cpu_median, cpu_p99, cpu_max;
    double gpu_mean, gpu_median;    /* -1: no frame's GPU time known */
};

static double mean_of(const double *values, uint32_t n)
{
    double sum = 0.0;
    for (uint32_t k = 0; k < n; k++)
        sum += values[k];
    return n ? sum / n : 0.0;
}

static void summarise(struct tw_method_summary *m, struct row *out)
{
    out->mean = mean_of(m->ms, m->frames);
    out->median = tw_report_percentile(m->ms, m->frames, 50.0);
    out->p95 = tw_report_percentile(m->ms, m->frames, 95.0);
    out->p99 = tw_report_percentile(m->ms, m->frames, 99.0);
    out->cpu_mean = mean_of(m->cpu_ms, m->frames);
    out->cpu_median = tw_report_percentile(m->cpu_ms, m->frames, 50.0);
    out->cpu_p99 = tw_report_percentile(m->cpu_ms, m->frames, 99.0);
    out->cpu_max = tw_report_percentile(m->cpu_ms, m->frames, 100.0);
    out->gpu_mean = m->gpu_frames ? mean_of(m->gpu_ms, m->gpu_frames) : -1.0;
    out->gpu_median = m->gpu_frames ? tw_report_percentile(m->gpu_ms, m->gpu_frames, 50.0) : -1.0;
    out->triangles = m->frames ? m->triangles / m->frames : 0.0;
    out->queries = m->frames ? m->queries / m->frames : 0.0;
}

/* "a / b" to three decimals, or "-" without a b (0). */
static void ratio(char *out, size_t size, double a, double b)
{
    if (b > 0.0)
        snprintf(out, size, "%.3f", a / b);
    else
        snprintf(out, size, "-");
}

/* A number written as it reads: json-c would print 17 significant digits. */
static json_object *number(double v, int decimals)
{
    char text[64];
    snprintf(text, sizeof(text), "%.*f", decimals, v);
    return json_object_new_double_s(v, text);
}

/* What a report says of a fact it was not given. */
static const char *known(const char *s)
{
    return s[0] ? s : "unknown";
}

/* A setting as it was given: 1e-05, 0.1. */
static json_object *number_g(double v)
{
    char text[64];
    snprintf(text, sizeof(text), "%g", v);
    return json_object_new_double_s(v, text);
}

/* --split: each method's CPU time parted into drawing its set and finding
 * it, against the oracle's frame (which draws the visible set). */
static void write_split(struct tw_outfile *f, const struct tw_report *r, const struct row *rows,
                        int nrows, const struct row *oracle)
{
    bool any = false;
    for (int k = 0; k < nrows; k++)
        any |= r->methods[rows[k].method].set_frames > 0;
    if (!any)
        return;
    tw_outfile_printf(f, "\n## Where the CPU time goes (--split)\n\n"
                         "Each frame's set of clusters drawn again from its camera with no "
                         "culling, tile by tile as the oracle draws its own (each tile's "
                         "clusters in the frame's order), and finished: what drawing that set "
                         "costs. The rest of the frame's "
                         "CPU time is what finding it cost (queries, waits, traversal). A "
                         "method that issues no query finds its set for next to nothing, and "
                         "what it reads there bounds what these figures can tell: the redraw "
                         "is one stretch of drawing, where a frame's queries flush the GPU's "
                         "work every tile, and on llvmpipe a large set can cost more drawn in "
                         "one stretch (see the README's known limits).\n\n"
                         "| method | CPU ms | drawing its set, CPU ms | finding it, CPU ms | "
                         "set / oracle's frame | triangles of the set | draws of the set |\n"
                         "|---|---|---|---|---|---|---|\n");
    for (int k = 0; k < nrows; k++) {
        const struct tw_method_summary *m = &r->methods[rows[k].method];
        if (m->set_frames == 0)
            continue;
        const double n = m->set_frames, set = m->set_cpu_ms / n;
        char so[32];
        ratio(so, sizeof(so), set, oracle ? oracle->cpu_mean : 0.0);
        tw_outfile_printf(f, "| %s | %.2f | %.2f | %.2f | %s | %.0f | %.0f |\n", rows[k].name,
                          rows[k].cpu_mean, set, rows[k].cpu_mean - set, so,
                          m->set_triangles / n, m->set_draws / n);
    }
}

/* With the box oracle in the run: each method against that floor. */
static void write_floor(struct tw_outfile *f, const struct row *rows, int nrows,
                        const struct row *oracle)
{
    const struct row *box = NULL;
    for (int k = 0; k < nrows; k++)
        if (rows[k].method == TW_METHOD_BOX_ORACLE)
            box = &rows[k];
    if (!box)
        return;
    char bo[32];
    ratio(bo, sizeof(bo), box->cpu_mean, oracle ? oracle->cpu_mean : 0.0);
    tw_outfile_printf(f, "\n## Against the box oracle (the floor of box tests)\n\n"
                         "The box oracle draws, with no query, every cluster that is visible or "
                         "whose box lies in front of the frame's true depth at some pixel: no "
                         "conservative method that culls by querying or depth-testing boxes "
                         "that contain the clusters' own can draw less. Its CPU time is %s of "
                         "the oracle's. A method's CPU time over the box oracle's is what "
                         "finding its set costs (queries, waits, traversal) and what its "
                         "traversal draws beyond the floor.\n\n"
                         "| method | CPU / box-oracle | triangles / box-oracle | triangles over "
                         "the floor |\n|---|---|---|---|\n", bo);
    for (int k = 0; k < nrows; k++) {
        if (tw_method_limit(rows[k].method))
            continue;
        char cb[32], tb[32];
        ratio(cb, sizeof(cb), rows[k].cpu_mean, box->cpu_mean);
        ratio(tb, sizeof(tb), rows[k].triangles, box->triangles);
        tw_outfile_printf(f, "| %s | %s | %s | %.0f |\n", rows[k].name, cb, tb,
                          rows[k].triangles - box->triangles);
    }
}

int tw_report_close(struct tw_report *r, bool markdown,
                    struct tw_method_figures figures[TW_METHOD_COUNT], char *err, size_t err_size)
{
    int rc = tw_outfile_commit(&r->frames_csv, err, err_size);
    for (int k = 0; k < TW_METHOD_COUNT && !rc; k++)
        if (r->chart_frames[k].f)
            rc = tw_outfile_commit(&r->chart_frames[k], err, err_size);
    if (rc) {
        tw_report_abort(r);
        return rc;
    }

    struct row rows[TW_METHOD_COUNT];
    int nrows = 0;
    if (figures)
        memset(figures, 0, sizeof(struct tw_method_figures) * TW_METHOD_COUNT);
    json_object *root = json_object_new_object();
    json_object *methods = json_object_new_object();
    for (int k = 0; k < TW_METHOD_COUNT; k++) {
        struct tw_method_summary *m = &r->methods[k];
        if (!m->used)
            continue;
        struct row *row = &rows[nrows++];
        row->name = tw_method_name((enum tw_method)k);
        row->method = (enum tw_method)k;
        summarise(m, row);
        json_object *o = json_object_new_object();
        json_object_object_add(o, "frames", json_object_new_int64(m->frames));
        json_object_object_add(o, "mean_ms", number(row->mean, 3));
        json_object_object_add(o, "median_ms", number(row->median, 3));
        json_object_object_add(o, "p95_ms", number(row->p95, 3));
        json_object_object_add(o, "p99_ms", number(row->p99, 3));
        json_object_object_add(o, "mean_triangles", number(row->triangles, 3));
        json_object_object_add(o, "mean_queries", number(row->queries, 3));
        json_object_object_add(o, "missed_pixels_total",
                               json_object_new_int64((int64_t)m->missed_pixels_total));
        json_object_object_add(o, "frames_with_missed_pixels",
                               json_object_new_int64(m->frames_with_missed_pixels));
        json_object_object_add(o, "tiles_new_total", json_object_new_int64((int64_t)m->tiles_new_total));
        json_object_object_add(o, "peak_cache_bytes",
                               json_object_new_int64((int64_t)m->peak_cache_bytes));
        json_object_object_add(o, "predict_fail_rate",
                               number(m->tiles_queried ? (double)m->predict_fail /
                                                             (double)m->tiles_queried : 0.0, 6));
        json_object_object_add(o, "mean_tiles_visible",
                               number(m->frames ? (double)m->tiles_visible / m->frames : 0.0, 3));
        json_object_object_add(o, "mean_ms_wait",
                               number(m->frames ? m->ms_wait / m->frames : 0.0, 3));
        json_object_object_add(o, "max_ms", number(m->ms_max, 3));
        json_object_object_add(o, "mean_overdraw_triangles",
                               number(m->frames ? m->overdraw_triangles / m->frames : 0.0, 1));
        json_object_object_add(o, "mean_overdraw_box_triangles",
                               number(m->frames ? m->overdraw_box_triangles / m->frames : 0.0, 1));
        json_object_object_add(o, "mean_cpu_ms", number(row->cpu_mean, 3));
        json_object_object_add(o, "median_cpu_ms", number(row->cpu_median, 3));
        json_object_object_add(o, "p99_cpu_ms", number(row->cpu_p99, 3));
        json_object_object_add(o, "max_cpu_ms", number(row->cpu_max, 3));
        json_object_object_add(o, "mean_gpu_ms", m->gpu_frames ? number(row->gpu_mean, 3) : NULL);
        json_object_object_add(o, "median_gpu_ms",
                               m->gpu_frames ? number(row->gpu_median, 3) : NULL);
        json_object_object_add(o, "gpu_frames_unknown",
                               json_object_new_int64(m->frames - m->gpu_frames));
        json_object_object_add(o, "missed_clusters_total",
                               json_object_new_int64((int64_t)m->missed_clusters_total));
        json_object_object_add(o, "depth_errors_total",
                               json_object_new_int64((int64_t)m->depth_errors_total));
        json_object_object_add(o, "frames_with_depth_errors",
                               json_object_new_int64(m->frames_with_depth_errors));
        if (m->set_frames > 0) {
            /* --split: the frames' sets drawn again with no culling. */
            const double n = m->set_frames;
            json_object *set = json_object_new_object();
            json_object_object_add(set, "frames", json_object_new_int64(m->set_frames));
            json_object_object_add(set, "mean_cpu_ms", number(m->set_cpu_ms / n, 3));
            json_object_object_add(set, "mean_ms", number(m->set_ms / n, 3));
            json_object_object_add(set, "mean_triangles", number(m->set_triangles / n, 1));
            json_object_object_add(set, "mean_draws", number(m->set_draws / n, 1));
            json_object_object_add(set, "mean_finding_cpu_ms",
                                   number(row->cpu_mean - m->set_cpu_ms / n, 3));
            json_object_object_add(o, "set", set);
        }
        json_object_object_add(methods, row->name, o);
        if (figures) {
            struct tw_method_figures *fg = &figures[k];
            fg->used = true;
            fg->frames = m->frames;
            fg->mean_ms = row->mean;
            fg->median_ms = row->median;
            fg->p95_ms = row->p95;
            fg->p99_ms = row->p99;
            fg->max_ms = m->ms_max;
            fg->mean_cpu_ms = row->cpu_mean;
            fg->median_cpu_ms = row->cpu_median;
            fg->p99_cpu_ms = row->cpu_p99;
            fg->max_cpu_ms = row->cpu_max;
            fg->mean_triangles = row->triangles;
            fg->mean_queries = row->queries;
            fg->mean_overdraw_triangles = m->frames ? m->overdraw_triangles / m->frames : 0.0;
            fg->mean_tiles_visible = m->frames ? (double)m->tiles_visible / m->frames : 0.0;
            fg->max_tiles_visible = m->max_tiles_visible;
            fg->missed_pixels_total = m->missed_pixels_total;
            fg->frames_with_missed_pixels = m->frames_with_missed_pixels;
            fg->missed_clusters_total = m->missed_clusters_total;
            fg->depth_errors_total = m->depth_errors_total;
            fg->frames_with_depth_errors = m->frames_with_depth_errors;
            fg->predict_fail_rate = m->tiles_queried ? (double)m->predict_fail / m->tiles_queried : 0.0;
            fg->peak_cache_bytes = m->peak_cache_bytes;
        }
    }
    json_object_object_add(root, "methods", methods);
    const struct tw_report_about *about = &r->about;
    json_object_object_add(root, "tileset", json_object_new_string(about->tileset));
    json_object_object_add(root, "path", json_object_new_string(about->path));
    char size[64];
    snprintf(size, sizeof(size), "%ux%u", about->width, about->height);
    json_object_object_add(root, "size", json_object_new_string(size));
    json_object_object_add(root, "seed", json_object_new_int64((int64_t)about->seed));
    json_object_object_add(root, "verified", json_object_new_boolean(about->verified));
    if (about->verified)
        json_object_object_add(root, "verify_tolerance", number_g(about->verify_tolerance));
    json_object_object_add(root, "deterministic", json_object_new_boolean(about->deterministic));
    if (about->mutate_query_shrink > 0.0f)
        json_object_object_add(root, "mutate_query_shrink", number_g(about->mutate_query_shrink));
    json_object *ran = json_object_new_object();
    json_object_object_add(ran, "context", json_object_new_string(known(about->context)));
    json_object_object_add(ran, "gl_vendor", json_object_new_string(known(about->gl_vendor)));
    json_object_object_add(ran, "gl_renderer", json_object_new_string(known(about->gl_renderer)));
    json_object_object_add(ran, "gl_version", json_object_new_string(known(about->gl_version)));
    json_object_object_add(ran, "software", json_object_new_boolean(about->software));
    json_object_object_add(ran, "build_type", json_object_new_string(known(about->build_type)));
    json_object_object_add(ran, "commit", json_object_new_string(known(about->commit)));
    json_object_object_add(root, "run", ran);
    char file[1100];
    snprintf(file, sizeof(file), "%s/summary.json", r->dir);
    rc = tw_report_write_json(file, root, JSON_C_TO_STRING_PRETTY | JSON_C_TO_STRING_SPACED, err,
                              err_size);
    json_object_put(root);

    if (markdown && rc == TW_OK) {
        snprintf(file, sizeof(file), "%s/summary.md", r->dir);
        struct tw_outfile f;
        rc = tw_outfile_open(&f, file, err, err_size);
        if (!rc) {
            const struct row *vfc = NULL, *oracle = NULL;
            for (int k = 0; k < nrows; k++) {
                if (rows[k].method == TW_METHOD_VFC) vfc = &rows[k];
                if (rows[k].method == TW_METHOD_ORACLE) oracle = &rows[k];
            }
            tw_outfile_printf(&f, "# tileworld bench: %s, path %s, %ux%u, seed %llu\n\n",
                              about->tileset, about->path, about->width, about->height,
                              (unsigned long long)about->seed);
            tw_outfile_printf(&f, "Ran on %s (%s, GL %s) through %s; %s build of %s.\n\n",
                              known(about->gl_renderer), known(about->gl_vendor),
                              known(about->gl_version), known(about->context),
                              known(about->build_type), known(about->commit));
            if (about->mutate_query_shrink > 0.0f)
                tw_outfile_printf(&f, "**Testing only: every query box shrunk by %g of its size "
                                      "(--mutate-query-shrink), a deliberately broken culler.**\n\n",
                                  about->mutate_query_shrink);
            tw_outfile_printf(&f, "| method | frames | mean ms | median ms | p95 ms | p99 ms | "
                                  "mean CPU ms | p99 CPU ms | mean GPU ms | triangles | queries | "
                                  "missed pixels | depth errors | time / vfc | CPU / vfc | "
                                  "triangles / vfc | time / oracle | CPU / oracle |\n");
            tw_outfile_printf(&f, "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
                                  "---|---|\n");
            for (int k = 0; k < nrows; k++) {
                const struct row *row = &rows[k];
                const struct tw_method_summary *m = &r->methods[row->method];
                char rv[32], cv[32], tv[32], ro[32], co[32], gpu[32];
                ratio(rv, sizeof(rv), row->mean, vfc ? vfc->mean : 0.0);
                ratio(cv, sizeof(cv), row->cpu_mean, vfc ? vfc->cpu_mean : 0.0);
                ratio(tv, sizeof(tv), row->triangles, vfc ? vfc->triangles : 0.0);
                ratio(ro, sizeof(ro), row->mean, oracle ? oracle->mean : 0.0);
                ratio(co, sizeof(co), row->cpu_mean, oracle ? oracle->cpu_mean : 0.0);
                if (row->gpu_mean >= 0.0)
                    snprintf(gpu, sizeof(gpu), "%.2f", row->gpu_mean);
                else
                    snprintf(gpu, sizeof(gpu), "-");
                tw_outfile_printf(&f, "| %s | %u | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %s | "
                                      "%.0f | %.1f | %llu | %llu | %s | %s | %s | %s | %s |\n",
                                  row->name, m->frames, row->mean, row->median, row->p95, row->p99,
                                  row->cpu_mean, row->cpu_p99, gpu, row->triangles, row->queries,
                                  (unsigned long long)m->missed_pixels_total,
                                  (unsigned long long)m->depth_errors_total, rv, cv, tv, ro, co);
            }
            write_floor(&f, rows, nrows, oracle);
            write_split(&f, r, rows, nrows, oracle);
            if (about->verified)
                tw_outfile_printf(&f, "\nAccuracy measured by the oracle (--verify) on every frame, "
                                      "depth tolerance %g (relative eye distance).\n",
                                  about->verify_tolerance);
            else
                tw_outfile_printf(&f, "\nAccuracy not measured (no --verify): missed pixels and "
                                      "depth errors read 0.\n");
            tw_outfile_printf(&f, "CPU ms is the process's CPU time of a frame, all threads (the "
                                  "software rasteriser's too): the figure that holds on a busy "
                                  "machine.\n");
            tw_outfile_printf(&f, "GPU ms is the frame's time on the GPU, from timestamp queries "
                                  "read once it had finished (an oracle's or --verify's ID pass "
                                  "apart; '-' where none came back).%s\n",
                              about->software
                                  ? " The renderer here is a software one: its GPU time is then "
                                    "the CPU rasteriser's work, whose threads' time CPU ms "
                                    "already counts."
                                  : "");
            tw_outfile_printf(&f, "\nRatios compare methods measured side by side in this one run; "
                                  "absolute times depend on the machine.\n");
            rc = tw_outfile_commit(&f, err, err_size);
        }
    }
    tw_report_abort(r);
    return rc;
}

void tw_report_abort(struct tw_report *r)
{
    tw_outfile_discard(&r->frames_csv);
    for (int k = 0; k < TW_METHOD_COUNT; k++) {
        tw_outfile_discard(&r->chart_frames[k]);
        free(r->methods[k].ms);
        free(r->methods[k].cpu_ms);
        free(r->methods[k].gpu_ms);
        memset(&r->methods[k], 0, sizeof(r->methods[k]));
    }
    r->open = false;
}
