/* frames.csv, the per-method chart data, summary.json and summary.md (report.h). */
#include "tiles/tiles-internal.h"
#include "tools/tileworld/report.h"

#include <errno.h>
#include <json-c/json.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "tileworld/tiles.h"

int tw_report_make_dirs(const char *dir)
{
    char buf[4096];
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
    "gpu_ms_id,waits,flushes,bytes_read_back,tiles_late,hzb_lag,lod_pixels,lod_pixels_exact,"
    "lod_depth_m,objects,object_cells,object_rebuilds,ms_objects\n";

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
             "%u,%u,%u,%.3f,%.3f,%llu,%u,%.3f,%.3f,%llu,%u,%llu,%.3f,%.3f,%u,%u,%llu,%u,%u,%llu,"
             "%llu,%.4f,%u,%u,%u,%.3f\n",
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
             (unsigned long long)st->overdraw_box_triangles, st->gpu_ms, st->gpu_ms_id, st->waits,
             st->flushes, (unsigned long long)st->bytes_read_back, st->tiles_late, st->hzb_lag,
             (unsigned long long)st->lod_pixels, (unsigned long long)st->lod_pixels_exact,
             st->lod_depth_m, st->objects, st->object_cells, st->object_rebuilds,
             st->ms_objects);
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
    const bool first = m->frames == 0;
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
    m->lod_pixels_total += st->lod_pixels;
    m->lod_depth_sum += st->lod_depth_m;
    m->ms_objects += st->ms_objects;
    m->object_rebuilds += st->object_rebuilds;
    m->tiles_new_total += st->tiles_new;
    if (st->cache_bytes > m->peak_instance_bytes)
        m->peak_instance_bytes = st->cache_bytes;
    if (st->bytes_cpu + st->bytes_gpu > r->peak_tile_cache_bytes)
        r->peak_tile_cache_bytes = st->bytes_cpu + st->bytes_gpu;
    m->predict_fail += st->predict_fail;
    m->tiles_queried += st->tiles_queried;
    m->tiles_visible += st->tiles_visible;
    if (st->tiles_visible > m->max_tiles_visible)
        m->max_tiles_visible = st->tiles_visible;
    m->ms_wait += st->ms_wait;
    m->waits += st->waits;
    m->flushes += st->flushes;
    m->bytes_read_back += (double)st->bytes_read_back;
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
        /* A method's first frame compiles shader variants and makes every
         * tile it draws; its set, drawn again, finds them ready (and is
         * itself timed on its second drawing): not comparable. */
        if (!first) {
            const double d = st->cpu_ms - set->cpu_ms;
            m->split_frames++;
            m->split_frame_cpu_ms += st->cpu_ms;
            m->split_set_cpu_ms += set->cpu_ms;
            m->split_set_ms += set->ms;
            m->split_diff += d;
            m->split_diff_sq += d * d;
        }
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

const char *tw_report_escape(const char *text, bool markdown, char *out, size_t size)
{
    if (!out || size == 0)
        return out;
    if (!markdown)
        return tw_log_escape(text, out, size);
    char *plain = malloc(size);
    if (!plain) {
        out[0] = '\0';
        return out;
    }
    tw_log_escape(text, plain, size);
    /* Entities for what would open a tag, a code span or a table cell;
     * a backslash before the rest of Markdown's punctuation. */
    size_t o = 0;
    for (const char *c = plain; *c; c++) {
        const char *piece = NULL;
        char two[3] = {'\\', *c, '\0'};
        switch (*c) {
        case '|': piece = "&#124;"; break;
        case '`': piece = "&#96;"; break;
        case '<': piece = "&lt;"; break;
        case '>': piece = "&gt;"; break;
        case '&': piece = "&amp;"; break;
        case '\\': case '*': case '_': case '[': case ']': case '#': case '~': case '!':
            piece = two;
            break;
        default:
            break;
        }
        const size_t len = piece ? strlen(piece) : 1;
        if (o + len + 4 > size) {
            memcpy(out + o, "...", 4);
            free(plain);
            return out;
        }
        if (piece)
            memcpy(out + o, piece, len);
        else
            out[o] = *c;
        o += len;
    }
    out[o] = '\0';
    free(plain);
    return out;
}

/* --split: the frames after the method's first, frame against set. */
static void split_figures(const struct tw_method_summary *m, struct tw_split_figures *out)
{
    memset(out, 0, sizeof(*out));
    const uint32_t n = m->split_frames;
    out->frames = n;
    if (n == 0)
        return;
    out->frame_cpu_ms = m->split_frame_cpu_ms / n;
    out->set_cpu_ms = m->split_set_cpu_ms / n;
    out->finding_cpu_ms = m->split_diff / n;
    if (n < TW_SPLIT_MIN_FRAMES)
        return;
    const double var = (m->split_diff_sq - m->split_diff * m->split_diff / n) / (n - 1);
    out->margin_cpu_ms = 2.0 * sqrt(var > 0.0 ? var / n : 0.0);
    const double at_most = out->finding_cpu_ms + out->margin_cpu_ms;
    if (out->finding_cpu_ms > out->margin_cpu_ms)
        out->verdict = TW_SPLIT_MEASURED;
    else if (at_most < 0.0)
        out->verdict = TW_SPLIT_NOT_MEASURABLE;
    else if (at_most >= out->frame_cpu_ms)
        out->verdict = TW_SPLIT_TOO_NOISY;
    else
        out->verdict = TW_SPLIT_BOUNDED;
}

static const char *split_verdict_name(enum tw_split_verdict v)
{
    switch (v) {
    case TW_SPLIT_MEASURED: return "measured";
    case TW_SPLIT_BOUNDED: return "not told apart from nothing";
    case TW_SPLIT_NOT_MEASURABLE: return "not measurable";
    case TW_SPLIT_TOO_NOISY: return "too noisy to tell";
    default: return "too few frames";
    }
}

/* --split: each method's CPU time parted into drawing its set and the rest,
 * over the frames where the two are comparable, against the oracle's frame
 * (which draws the visible set). */
static void write_split(struct tw_outfile *f, const struct tw_report *r, const struct row *rows,
                        int nrows, const struct row *oracle)
{
    bool any = false;
    for (int k = 0; k < nrows; k++)
        any |= r->methods[rows[k].method].set_frames > 0;
    if (!any)
        return;
    tw_outfile_printf(f, "\n## Where the CPU time goes (--split)\n\n"
                         "After each frame its set of clusters was drawn again from its camera "
                         "with no culling and no query, tile by tile as the oracle draws its "
                         "own, and finished: what drawing that set costs. A method's first "
                         "frame is left out (it compiles shader variants and makes every tile "
                         "it draws, which its set, drawn again, finds ready); over the other "
                         "frames the frame's mean CPU time is the set's plus the rest: finding "
                         "the set (queries, waits, traversal) and the frame's tile bookkeeping. "
                         "The rest is a difference of two noisy times: it is given when it "
                         "exceeds twice its standard error (the margin), bounded when it does "
                         "not, too noisy to tell when that bound is as large as the frame, and "
                         "not measurable when the set drawn again cost more than its frame "
                         "beyond that margin (on a software rasteriser a set drawn in one "
                         "stretch can cost more than the same set drawn between queries, in "
                         "pieces).\n\n"
                         "| method | frames compared | frame, CPU ms | drawing its set, CPU ms | "
                         "the rest (finding), CPU ms | set / oracle's frame | triangles of the "
                         "set | draws of the set |\n"
                         "|---|---|---|---|---|---|---|---|\n");
    for (int k = 0; k < nrows; k++) {
        const struct tw_method_summary *m = &r->methods[rows[k].method];
        if (m->set_frames == 0)
            continue;
        struct tw_split_figures sp;
        split_figures(m, &sp);
        const double n = m->set_frames;
        char so[32], drawing[96], finding[160];
        ratio(so, sizeof(so), sp.set_cpu_ms, oracle ? oracle->cpu_mean : 0.0);
        switch (sp.verdict) {
        case TW_SPLIT_MEASURED:
            snprintf(drawing, sizeof(drawing), "%.2f", sp.set_cpu_ms);
            snprintf(finding, sizeof(finding), "%.2f (margin %.2f)", sp.finding_cpu_ms,
                     sp.margin_cpu_ms);
            break;
        case TW_SPLIT_BOUNDED:
            snprintf(drawing, sizeof(drawing), "at least %.2f",
                     sp.frame_cpu_ms - (sp.finding_cpu_ms + sp.margin_cpu_ms));
            snprintf(finding, sizeof(finding), "at most %.2f (not told apart from nothing)",
                     sp.finding_cpu_ms + sp.margin_cpu_ms);
            break;
        case TW_SPLIT_NOT_MEASURABLE:
            snprintf(drawing, sizeof(drawing), "not measurable");
            snprintf(finding, sizeof(finding), "not measurable: its set drawn again cost "
                     "%.2f, more than its frame beyond the margin of %.2f", sp.set_cpu_ms,
                     sp.margin_cpu_ms);
            break;
        case TW_SPLIT_TOO_NOISY:
            snprintf(drawing, sizeof(drawing), "too noisy to tell");
            snprintf(finding, sizeof(finding), "too noisy to tell: the margin, %.2f, is as "
                     "large as the frame", sp.margin_cpu_ms);
            break;
        default:
            snprintf(drawing, sizeof(drawing), "not measured");
            snprintf(finding, sizeof(finding), "not measured: fewer than %d frames after the "
                     "first", TW_SPLIT_MIN_FRAMES);
            break;
        }
        if (sp.verdict == TW_SPLIT_NONE)
            snprintf(so, sizeof(so), "-");
        tw_outfile_printf(f, "| %s | %u | %.2f | %s | %s | %s | %.0f | %.0f |\n", rows[k].name,
                          sp.frames, sp.frame_cpu_ms, drawing, finding, so,
                          m->set_triangles / n, m->set_draws / n);
    }
}

/* ---- the verdict ----------------------------------------------------------------- */

/* The figure methods are ranked by: CPU time on a software renderer (its
 * GPU work is CPU work), the time to a finished frame on a GPU. */
static double ranked_figure(const struct tw_method_figures *fg, bool software)
{
    return software ? fg->mean_cpu_ms : fg->mean_ms;
}

/* Appends to a verdict line (cut at its end). */
static void add(char *line, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
static void add(char *line, const char *fmt, ...)
{
    const size_t n = strlen(line), size = sizeof(((struct tw_verdict *)0)->lines[0]);
    if (n + 1 >= size)
        return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(line + n, size - n, fmt, ap);
    va_end(ap);
}

/* " (0.135x vfc's, 1.33x the box oracle's)" for a figure a of a method
 * against those of vfc and the box oracle (0: not in the run); short: " (0.135x, 1.33x)". */
static void add_ratios(char *line, double a, double vfc, double box, bool short_form)
{
    if (vfc > 0.0 && box > 0.0)
        add(line, short_form ? " (%.3gx, %.3gx)" : " (%.3gx vfc's, %.3gx the box oracle's)",
            a / vfc, a / box);
    else if (vfc > 0.0)
        add(line, short_form ? " (%.3gx)" : " (%.3gx vfc's)", a / vfc);
    else if (box > 0.0)
        add(line, short_form ? " (%.3gx)" : " (%.3gx the box oracle's)", a / box);
}

bool tw_report_missed(const struct tw_report_about *about,
                      const struct tw_method_figures figures[TW_METHOD_ALL])
{
    if (!about->verified)
        return false;
    for (int k = 0; k < TW_METHOD_ALL; k++)
        if (figures[k].used && about->conservative[k] && figures[k].missed_pixels_total > 0)
            return true;
    return false;
}

void tw_report_verdict(const struct tw_report_about *about,
                       const struct tw_method_figures figures[TW_METHOD_ALL], bool bench,
                       enum tw_verdict_form form, struct tw_verdict *out)
{
    memset(out, 0, sizeof(*out));
    const bool md = form == TW_VERDICT_MARKDOWN;
    const bool sw = about->software;
    char tileset[300], path[300], renderer[300], context[64], build[64], commit[100];
    tw_report_escape(about->tileset, md, tileset, sizeof(tileset));
    tw_report_escape(about->path, md, path, sizeof(path));
    tw_report_escape(known(about->gl_renderer), md, renderer, sizeof(renderer));
    tw_report_escape(known(about->context), md, context, sizeof(context));
    tw_report_escape(known(about->build_type), md, build, sizeof(build));
    tw_report_escape(known(about->commit), md, commit, sizeof(commit));
    int used = 0;
    enum tw_method only = TW_METHOD_VFC;
    for (int k = 0; k < TW_METHOD_ALL; k++)
        if (figures[k].used) {
            used++;
            only = (enum tw_method)k;
        }
    const struct tw_method_figures *vfc = &figures[TW_METHOD_VFC];
    const struct tw_method_figures *box = &figures[TW_METHOD_BOX_ORACLE];
    const char *metric = sw ? "CPU time" : "time to a finished frame (wall)";

    /* What ran, where. */
    char *line = out->lines[out->count++];
    if (bench)
        add(line, "tileworld bench of %d method%s", used, used == 1 ? "" : "s");
    else
        add(line, "tileworld walk with %s", tw_method_name(only));
    char cars[64] = "";
    if (about->cars)
        snprintf(cars, sizeof(cars), ", %u moving car%s", about->cars, about->cars == 1 ? "" : "s");
    add(line, ": tileset %s%s, path %s%s, %ux%u, %u frames, seed %llu; on %s through %s%s; %s "
              "build of %s.", tileset, cars, path,
        about->views > 1 ? " and a chase camera as a second view" : "", about->width,
        about->height, about->frames, (unsigned long long)about->seed, renderer, context,
        sw ? " (a software renderer: its GPU work is CPU time)" : " (a GPU)", build, commit);

    /* How fast. */
    line = out->lines[out->count++];
    if (!bench || used == 1) {
        const struct tw_method_figures *fg = &figures[only];
        add(line, "%s: %.2f ms of CPU time a frame, %.2f ms to a finished frame (wall)",
            tw_method_name(only), fg->mean_cpu_ms, fg->mean_ms);
        if (fg->gpu_frames > 0)
            add(line, ", %.2f ms of GPU time%s", fg->mean_gpu_ms,
                sw ? " (the software rasteriser's work, counted in the CPU time too)" : "");
        else
            add(line, ", GPU time not known");
        const bool reference = only == TW_METHOD_VFC || only == TW_METHOD_BOX_ORACLE;
        add(line, ". Ratios to vfc and to the box oracle need them in the same run: tileworld "
                  "bench --methods vfc,%s%sbox-oracle.",
            reference ? "" : tw_method_name(only), reference ? "" : ",");
    } else {
        /* The conservative methods a renderer could use, by the figure. */
        enum tw_method best = TW_METHOD_ALL, next = TW_METHOD_ALL;
        for (int k = 0; k < TW_METHOD_ALL; k++) {
            const struct tw_method_figures *fg = &figures[k];
            if (!fg->used || tw_method_limit((enum tw_method)k) || !about->conservative[k])
                continue;
            const double v = ranked_figure(fg, sw);
            if (best == TW_METHOD_ALL || v < ranked_figure(&figures[best], sw)) {
                next = best;
                best = (enum tw_method)k;
            } else if (next == TW_METHOD_ALL || v < ranked_figure(&figures[next], sw)) {
                next = (enum tw_method)k;
            }
        }
        if (best == TW_METHOD_ALL) {
            add(line, "No conservative method a renderer could use ran (see --methods and "
                      "--threshold): none is ranked.");
        } else {
            const struct tw_method_figures *fg = &figures[best];
            const double rv = vfc->used && best != TW_METHOD_VFC ? 1.0 : 0.0;
            const double rb = box->used ? 1.0 : 0.0;
            /* The ranked figure first, then the others. */
            const double cpu[3] = {fg->mean_cpu_ms, rv * vfc->mean_cpu_ms, rb * box->mean_cpu_ms};
            const double wall[3] = {fg->mean_ms, rv * vfc->mean_ms, rb * box->mean_ms};
            add(line, "Fastest conservative method, by %s: %s, ", metric, tw_method_name(best));
            for (int pass = 0; pass < 2; pass++) {
                const bool cpu_pass = (pass == 0) == sw;
                const double *v = cpu_pass ? cpu : wall;
                add(line, cpu_pass ? "%s%.2f ms of CPU time a frame"
                                   : "%s%.2f ms to a finished frame (wall)", pass ? "; " : "", v[0]);
                add_ratios(line, v[0], v[1], v[2], pass > 0);
            }
            if (fg->gpu_frames > 0) {
                add(line, "; %.2f ms of GPU time", fg->mean_gpu_ms);
                add_ratios(line, fg->mean_gpu_ms, rv * (vfc->gpu_frames ? vfc->mean_gpu_ms : 0.0),
                           rb * (box->gpu_frames ? box->mean_gpu_ms : 0.0), true);
            } else {
                add(line, "; GPU time not known");
            }
            add(line, ".");
            if (next != TW_METHOD_ALL) {
                const double a = ranked_figure(fg, sw), b = ranked_figure(&figures[next], sw);
                add(line, " The next fastest, %s, took %.2fx as much %s.", tw_method_name(next),
                    a > 0.0 ? b / a : 0.0, sw ? "CPU time" : "wall time");
            }
            if (!vfc->used)
                add(line, " (vfc was not in this run.)");
            if (!box->used)
                add(line, " (box-oracle, the floor of culling with boxes, was not in this run.)");
        }
        /* Every method against the references, by the same figure. */
        if (vfc->used || box->used) {
            line = out->lines[out->count++];
            add(line, "%s per frame, as a multiple of %s%s%s:", sw ? "CPU time" : "Wall time",
                vfc->used ? "vfc's" : "", vfc->used && box->used ? " / " : "",
                box->used ? "the box oracle's" : "");
            bool comma = false;
            for (int k = 0; k < TW_METHOD_ALL; k++) {
                const struct tw_method_figures *fg = &figures[k];
                if (!fg->used)
                    continue;
                const double v = ranked_figure(fg, sw);
                const double a = ranked_figure(vfc, sw), b = ranked_figure(box, sw);
                add(line, "%s %s ", comma ? "," : "", tw_method_name((enum tw_method)k));
                if (vfc->used)
                    add(line, "%.3g", a > 0.0 ? v / a : 0.0);
                if (vfc->used && box->used)
                    add(line, " / ");
                if (box->used)
                    add(line, "%.3g", b > 0.0 ? v / b : 0.0);
                if (tw_method_limit((enum tw_method)k))
                    add(line, " (a limit)");
                else if (!about->conservative[k])
                    add(line, " (approximate)");
                comma = true;
            }
            add(line, ".");
        }
    }

    /* How accurate. */
    line = out->lines[out->count++];
    if (!about->verified) {
        add(line, "Accuracy not measured (add --verify).");
    } else {
        out->failed = tw_report_missed(about, figures);
        if (out->failed) {
            add(line, "%sFAILED: a conservative method missed pixels under --verify:",
                md ? "**" : "");
            bool comma = false;
            for (int k = 0; k < TW_METHOD_ALL; k++) {
                const struct tw_method_figures *fg = &figures[k];
                if (!fg->used || !about->conservative[k] || fg->missed_pixels_total == 0)
                    continue;
                add(line, "%s %s missed %llu pixels in %u of %u frames", comma ? "," : "",
                    tw_method_name((enum tw_method)k),
                    (unsigned long long)fg->missed_pixels_total, fg->frames_with_missed_pixels,
                    fg->frames);
                comma = true;
            }
            add(line, "; it must miss none. %s%s",
                about->allow_missed ? "Accepted by --allow-missed (exit status 0)."
                                    : "Exit status 3 (--allow-missed accepts it).",
                md ? "**" : "");
        } else {
            if (used == 1)
                add(line, "Accuracy (--verify, the oracle's ID pass on every frame): %s missed no "
                          "pixel.", tw_method_name(only));
            else
                add(line, "Accuracy (--verify, the oracle's ID pass on every frame): no "
                          "conservative method missed a pixel.");
        }
        for (int k = 0; k < TW_METHOD_ALL; k++) {
            const struct tw_method_figures *fg = &figures[k];
            if (fg->used && !about->conservative[k])
                add(line, " %s, approximate (--threshold), missed %llu pixels in %u of %u frames.",
                    tw_method_name((enum tw_method)k),
                    (unsigned long long)fg->missed_pixels_total, fg->frames_with_missed_pixels,
                    fg->frames);
        }
    }
    if (about->verified && about->max_screen_error > 0.0f) {
        add(line, " Levels of detail (--max-screen-error %g): pixels differing from full "
                  "detail,", about->max_screen_error);
        bool comma = false;
        for (int k = 0; k < TW_METHOD_ALL; k++) {
            const struct tw_method_figures *fg = &figures[k];
            if (!fg->used)
                continue;
            add(line, "%s %s %.3f %%", comma ? "," : "", tw_method_name((enum tw_method)k),
                100.0 * fg->lod_pixel_fraction);
            comma = true;
        }
        add(line, " of the image a frame.");
    } else if (about->verified) {
        add(line, " Full detail (--max-screen-error 0).");
    }
    if (about->mutate_query_shrink > 0.0f)
        add(line, " %sTesting only: every query box shrunk by %g of its size "
                  "(--mutate-query-shrink), a deliberately broken culler.%s",
            md ? "**" : "", about->mutate_query_shrink, md ? "**" : "");
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

/* An object of named counts. */
static json_object *counts(const char *const *names, const uint64_t *v, int n)
{
    json_object *o = json_object_new_object();
    for (int k = 0; k < n; k++)
        json_object_object_add(o, names[k], json_object_new_int64((int64_t)v[k]));
    return o;
}

int tw_report_close(struct tw_report *r, bool markdown,
                    struct tw_method_figures figures[TW_METHOD_ALL], char *err, size_t err_size)
{
    int rc = tw_outfile_commit(&r->frames_csv, err, err_size);
    for (int k = 0; k < TW_METHOD_ALL && !rc; k++)
        if (r->chart_frames[k].f)
            rc = tw_outfile_commit(&r->chart_frames[k], err, err_size);
    if (rc) {
        tw_report_abort(r);
        return rc;
    }

    struct row rows[TW_METHOD_ALL];
    int nrows = 0;
    /* The figures are the verdict's too: kept here when the caller wants none. */
    struct tw_method_figures own[TW_METHOD_ALL];
    struct tw_method_figures *figures_of = figures ? figures : own;
    memset(figures_of, 0, sizeof(struct tw_method_figures) * TW_METHOD_ALL);
    json_object *root = json_object_new_object();
    json_object *methods = json_object_new_object();
    for (int k = 0; k < TW_METHOD_ALL; k++) {
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
        /* Accuracy not measured is null, never 0. */
        const bool verified = r->about.verified;
        json_object_object_add(o, "missed_pixels_total",
                               verified ? json_object_new_int64((int64_t)m->missed_pixels_total)
                                        : NULL);
        json_object_object_add(o, "frames_with_missed_pixels",
                               verified ? json_object_new_int64(m->frames_with_missed_pixels)
                                        : NULL);
        /* What levels of detail change against full detail (with verify). */
        const bool lod = verified && r->about.max_screen_error > 0.0f && m->frames;
        const double npix = (double)r->about.width * r->about.height;
        json_object_object_add(o, "lod_pixels_per_frame",
                               lod ? number((double)m->lod_pixels_total / m->frames, 1) : NULL);
        json_object_object_add(o, "lod_pixel_fraction",
                               lod && npix > 0 ? number((double)m->lod_pixels_total /
                                                            m->frames / npix, 7)
                                               : NULL);
        json_object_object_add(o, "lod_depth_m_mean",
                               lod ? number(m->lod_depth_sum / m->frames, 4) : NULL);
        json_object_object_add(o, "tiles_new_total", json_object_new_int64((int64_t)m->tiles_new_total));
        json_object_object_add(o, "peak_instance_bytes",
                               json_object_new_int64((int64_t)m->peak_instance_bytes));
        json_object_object_add(o, "predict_fail_rate",
                               number(m->tiles_queried ? (double)m->predict_fail /
                                                             (double)m->tiles_queried : 0.0, 6));
        json_object_object_add(o, "mean_tiles_visible",
                               number(m->frames ? (double)m->tiles_visible / m->frames : 0.0, 3));
        json_object_object_add(o, "mean_waits",
                               number(m->frames ? (double)m->waits / m->frames : 0.0, 2));
        json_object_object_add(o, "mean_flushes",
                               number(m->frames ? (double)m->flushes / m->frames : 0.0, 2));
        json_object_object_add(o, "mean_bytes_read_back",
                               number(m->frames ? m->bytes_read_back / m->frames : 0.0, 1));
        json_object_object_add(o, "mean_ms_objects",
                               number(m->frames ? m->ms_objects / m->frames : 0.0, 3));
        json_object_object_add(o, "mean_object_rebuilds",
                               number(m->frames ? (double)m->object_rebuilds / m->frames : 0.0, 2));
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
                               verified ? json_object_new_int64((int64_t)m->missed_clusters_total)
                                        : NULL);
        json_object_object_add(o, "depth_errors_total",
                               verified ? json_object_new_int64((int64_t)m->depth_errors_total)
                                        : NULL);
        json_object_object_add(o, "frames_with_depth_errors",
                               verified ? json_object_new_int64(m->frames_with_depth_errors)
                                        : NULL);
        struct tw_split_figures split;
        split_figures(m, &split);
        if (m->set_frames > 0) {
            /* --split: the frames' sets drawn again with no culling, over
             * the frames compared (all but the method's first). */
            const double n = m->set_frames;
            const bool given = split.verdict == TW_SPLIT_MEASURED;
            json_object *set = json_object_new_object();
            json_object_object_add(set, "frames", json_object_new_int64(split.frames));
            json_object_object_add(set, "mean_frame_cpu_ms", number(split.frame_cpu_ms, 3));
            json_object_object_add(set, "mean_cpu_ms", number(split.set_cpu_ms, 3));
            json_object_object_add(set, "mean_ms", number(split.frames ? m->split_set_ms /
                                                                          split.frames : 0.0, 3));
            json_object_object_add(set, "mean_triangles", number(m->set_triangles / n, 1));
            json_object_object_add(set, "mean_draws", number(m->set_draws / n, 1));
            json_object_object_add(set, "finding", json_object_new_string(
                                       split_verdict_name(split.verdict)));
            json_object_object_add(set, "mean_finding_cpu_ms",
                                   given ? number(split.finding_cpu_ms, 3) : NULL);
            json_object_object_add(set, "finding_at_most_cpu_ms",
                                   split.verdict == TW_SPLIT_BOUNDED
                                       ? number(split.finding_cpu_ms + split.margin_cpu_ms, 3)
                                       : NULL);
            json_object_object_add(set, "finding_margin_cpu_ms",
                                   split.verdict != TW_SPLIT_NONE ? number(split.margin_cpu_ms, 3)
                                                                  : NULL);
            json_object_object_add(o, "set", set);
        }
        json_object_object_add(methods, row->name, o);
        {
            struct tw_method_figures *fg = &figures_of[k];
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
            fg->lod_pixels_total = m->lod_pixels_total;
            fg->lod_pixel_fraction =
                m->frames && r->about.width ? (double)m->lod_pixels_total / m->frames /
                                                ((double)r->about.width * r->about.height)
                                          : 0.0;
            fg->predict_fail_rate = m->tiles_queried ? (double)m->predict_fail / m->tiles_queried : 0.0;
            fg->peak_instance_bytes = m->peak_instance_bytes;
            fg->mean_gpu_ms = row->gpu_mean;
            fg->gpu_frames = m->gpu_frames;
            fg->split = split;
        }
    }
    json_object_object_add(root, "methods", methods);
    const struct tw_report_about *about = &r->about;
    /* Names from input: valid UTF-8 with no control character (json-c
     * writes bytes as they are). */
    char text[1024];
    json_object_object_add(root, "tileset", json_object_new_string(
                               tw_report_escape(about->tileset, false, text, sizeof(text))));
    json_object_object_add(root, "path", json_object_new_string(
                               tw_report_escape(about->path, false, text, sizeof(text))));
    json_object_object_add(root, "peak_tile_cache_bytes",
                           json_object_new_int64((int64_t)r->peak_tile_cache_bytes));
    char size[64];
    snprintf(size, sizeof(size), "%ux%u", about->width, about->height);
    json_object_object_add(root, "size", json_object_new_string(size));
    json_object_object_add(root, "seed", json_object_new_int64((int64_t)about->seed));
    json_object_object_add(root, "verified", json_object_new_boolean(about->verified));
    if (about->verified)
        json_object_object_add(root, "verify_tolerance", number_g(about->verify_tolerance));
    json_object_object_add(root, "deterministic", json_object_new_boolean(about->deterministic));
    json_object_object_add(root, "views", json_object_new_int64(about->views ? about->views : 1));
    json_object_object_add(root, "cars", json_object_new_int64(about->cars));
    if (about->mutate_query_shrink > 0.0f)
        json_object_object_add(root, "mutate_query_shrink", number_g(about->mutate_query_shrink));
    if (about->has_totals) {
        const struct tw_cache_totals *t = &about->totals;
        const char *names[] = {"loads_requested", "loads_done", "evictions", "reloads",
                               "refused"};
        const uint64_t v[] = {t->loads_requested, t->loads_done, t->evictions, t->reloads,
                              t->refused};
        json_object_object_add(root, "tile_cache", counts(names, v, 5));
    }
    if (about->has_tiles3d) {
        const struct tw_tiles3d_stats *h = &about->tiles3d;
        const char *names[] = {"cells", "blocks", "requests", "bytes", "cache_hits",
                               "not_modified", "retries", "failures", "stale"};
        const uint64_t v[] = {h->cells, h->blocks, h->requests, h->bytes, h->cache_hits,
                              h->not_modified, h->retries, h->failures, h->stale};
        json_object_object_add(root, "tiles3d", counts(names, v, 9));
    }
    json_object *ran = json_object_new_object();
    json_object_object_add(ran, "context", json_object_new_string(
                               tw_report_escape(known(about->context), false, text, sizeof(text))));
    json_object_object_add(ran, "gl_vendor", json_object_new_string(
                               tw_report_escape(known(about->gl_vendor), false, text, sizeof(text))));
    json_object_object_add(ran, "gl_renderer", json_object_new_string(
                               tw_report_escape(known(about->gl_renderer), false, text, sizeof(text))));
    json_object_object_add(ran, "gl_version", json_object_new_string(
                               tw_report_escape(known(about->gl_version), false, text, sizeof(text))));
    json_object_object_add(ran, "software", json_object_new_boolean(about->software));
    json_object_object_add(ran, "build_type", json_object_new_string(
                               tw_report_escape(known(about->build_type), false, text, sizeof(text))));
    json_object_object_add(ran, "commit", json_object_new_string(
                               tw_report_escape(known(about->commit), false, text, sizeof(text))));
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
            /* The verdict first, then what ran, before any table. */
            char tileset[600], path[600], vendor[300], version[300];
            tw_outfile_printf(&f, "# tileworld %s: %s, path %s, %ux%u, seed %llu\n\n",
                              about->bench ? "bench" : "walk", tw_report_escape(about->tileset, true, tileset, sizeof(tileset)),
                              tw_report_escape(about->path, true, path, sizeof(path)),
                              about->width, about->height, (unsigned long long)about->seed);
            struct tw_verdict verdict;
            tw_report_verdict(about, figures_of, about->bench, TW_VERDICT_MARKDOWN, &verdict);
            /* Its first line says what ran: the line below says more. */
            for (int k = 1; k < verdict.count; k++)
                tw_outfile_printf(&f, "%s\n", verdict.lines[k]);
            char renderer[600], context[100], build[100], commit[200];
            char cars[64] = "";
            if (about->cars)
                snprintf(cars, sizeof(cars), " with %u moving car%s", about->cars,
                         about->cars == 1 ? "" : "s");
            tw_outfile_printf(&f, "\nRan on %s (%s, GL %s) through %s; %s build of %s; tileset "
                                  "%s%s, path %s, %ux%u, %u frames, seed %llu.\n\n",
                              tw_report_escape(known(about->gl_renderer), true, renderer,
                                               sizeof(renderer)),
                              tw_report_escape(known(about->gl_vendor), true, vendor,
                                               sizeof(vendor)),
                              tw_report_escape(known(about->gl_version), true, version,
                                               sizeof(version)),
                              tw_report_escape(known(about->context), true, context,
                                               sizeof(context)),
                              tw_report_escape(known(about->build_type), true, build,
                                               sizeof(build)),
                              tw_report_escape(known(about->commit), true, commit, sizeof(commit)),
                              tileset, cars, path, about->width, about->height, about->frames,
                              (unsigned long long)about->seed);
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
                char missed[32] = "not measured", depth[32] = "not measured";
                if (about->verified) {
                    snprintf(missed, sizeof(missed), "%llu",
                             (unsigned long long)m->missed_pixels_total);
                    snprintf(depth, sizeof(depth), "%llu",
                             (unsigned long long)m->depth_errors_total);
                }
                tw_outfile_printf(&f, "| %s | %u | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %s | "
                                      "%.0f | %.1f | %s | %s | %s | %s | %s | %s | %s |\n",
                                  row->name, m->frames, row->mean, row->median, row->p95, row->p99,
                                  row->cpu_mean, row->cpu_p99, gpu, row->triangles, row->queries,
                                  missed, depth, rv, cv, tv, ro, co);
            }
            write_floor(&f, rows, nrows, oracle);
            write_split(&f, r, rows, nrows, oracle);
            if (about->verified)
                tw_outfile_printf(&f, "\nAccuracy measured by the oracle (--verify) on every frame, "
                                      "depth tolerance %g (relative eye distance).\n",
                                  about->verify_tolerance);
            else
                tw_outfile_printf(&f, "\nAccuracy not measured (no --verify).\n");
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
    for (int k = 0; k < TW_METHOD_ALL; k++) {
        tw_outfile_discard(&r->chart_frames[k]);
        free(r->methods[k].ms);
        free(r->methods[k].cpu_ms);
        free(r->methods[k].gpu_ms);
        memset(&r->methods[k], 0, sizeof(r->methods[k]));
    }
    r->open = false;
}
