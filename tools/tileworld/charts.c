/* Charts of a bench run: data files from memory, the built-in charts.gp, gnuplot (charts.h). */
#include "tools/tileworld/charts.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "tools/outfile.h"
#include "tools/charts-gp.h"   /* TW_CHARTS_GP: tools/tileworld/charts.gp, built in */

extern char **environ;

#define DATA TW_REPORT_CHART_DATA

/* The columns of methods.dat (after method) and of sweep-METHOD.dat (after
 * value), named as in summary.json. */
static const char figures_header[] =
    "frames mean_ms median_ms p95_ms p99_ms max_ms mean_triangles mean_queries "
    "mean_overdraw_triangles missed_pixels_total frames_with_missed_pixels "
    "mean_cpu_ms median_cpu_ms p99_cpu_ms depth_errors_total frames_with_depth_errors "
    "missed_clusters_total\n";

static void put_figures(struct tw_outfile *o, const struct tw_method_figures *fg)
{
    tw_outfile_printf(o, "%u %.3f %.3f %.3f %.3f %.3f %.3f %.3f %.3f %llu %u %.3f %.3f %.3f %llu %u "
                      "%llu\n", fg->frames,
                      fg->mean_ms, fg->median_ms, fg->p95_ms, fg->p99_ms, fg->max_ms,
                      fg->mean_triangles, fg->mean_queries, fg->mean_overdraw_triangles,
                      (unsigned long long)fg->missed_pixels_total, fg->frames_with_missed_pixels,
                      fg->mean_cpu_ms, fg->median_cpu_ms, fg->p99_cpu_ms,
                      (unsigned long long)fg->depth_errors_total, fg->frames_with_depth_errors,
                      (unsigned long long)fg->missed_clusters_total);
}

static int open_in(struct tw_outfile *o, const char *dir, const char *name, char *err,
                   size_t err_size)
{
    char file[TW_OUTFILE_PATH];
    const int n = snprintf(file, sizeof(file), "%s/%s", dir, name);
    if (n < 0 || (size_t)n >= sizeof(file)) {
        snprintf(err, err_size, "%s: the folder name is too long", dir);
        return TW_ERR_IO;
    }
    return tw_outfile_open(o, file, err, err_size);
}

static int write_methods(const struct tw_chart_run *run, char *err, size_t err_size)
{
    struct tw_outfile o;
    int rc = open_in(&o, run->dir, DATA "/methods.dat", err, err_size);
    if (rc)
        return rc;
    tw_outfile_printf(&o, "# one row per method, in the order of the run\nmethod %s", figures_header);
    for (uint32_t k = 0; k < run->method_count; k++) {
        tw_outfile_printf(&o, "%s ", tw_method_name(run->methods[k]));
        put_figures(&o, &run->figures[run->methods[k]]);
    }
    return tw_outfile_commit(&o, err, err_size);
}

/* A parameter that leaves a method's triangles, missed pixels and overdraw
 * the same at every value changes nothing it draws (T for vfc): its points
 * differ only by timing noise. */
static bool unaffected(const struct tw_chart_sweep *s, enum tw_method m)
{
    if (s->count < 2)
        return false;
    const struct tw_method_figures *first = &s->figures[0][m];
    for (uint32_t k = 1; k < s->count; k++) {
        const struct tw_method_figures *fg = &s->figures[k][m];
        if (fg->mean_triangles != first->mean_triangles ||
            fg->missed_pixels_total != first->missed_pixels_total ||
            fg->mean_overdraw_triangles != first->mean_overdraw_triangles)
            return false;
    }
    return true;
}

/* The sweep's values in ascending order, as indices. */
static void sort_values(const struct tw_chart_sweep *s, uint32_t *order)
{
    for (uint32_t k = 0; k < s->count; k++) {
        uint32_t j = k;
        for (; j > 0 && s->values[order[j - 1]] > s->values[k]; j--)
            order[j] = order[j - 1];
        order[j] = k;
    }
}

static int write_sweep(const struct tw_chart_run *run, const uint32_t *order, char *err,
                       size_t err_size)
{
    const struct tw_chart_sweep *s = run->sweep;
    for (uint32_t m = 0; m < run->method_count; m++) {
        const enum tw_method me = run->methods[m];
        char name[128];
        snprintf(name, sizeof(name), DATA "/sweep-%s.dat", tw_method_name(me));
        struct tw_outfile o;
        int rc = open_in(&o, run->dir, name, err, err_size);
        if (rc)
            return rc;
        tw_outfile_printf(&o, "# %s: one row per value of %s, by value\nvalue %s", tw_method_name(me),
                          s->param, figures_header);
        for (uint32_t k = 0; k < s->count; k++) {
            tw_outfile_printf(&o, "%g ", s->values[order[k]]);
            put_figures(&o, &s->figures[order[k]][me]);
        }
        if ((rc = tw_outfile_commit(&o, err, err_size)))
            return rc;
    }
    return TW_OK;
}

/* Speed against accuracy: chart-data/pareto.dat (every point) and
 * pareto-front.dat, pareto-front-depth.dat (the points of each front),
 * each by CPU time, so that a front's points join in order. */
static int write_pareto(const struct tw_chart_run *run, char *err, size_t err_size)
{
    static const char *const names[3] = {
        DATA "/pareto.dat", DATA "/pareto-front.dat", DATA "/pareto-front-depth.dat",
    };
    static const char *const what[3] = {
        "every point", "the front of CPU time against missed pixels",
        "the front of CPU time against depth errors",
    };
    const struct tw_chart_sweep *s = run->sweep;
    uint32_t order[64 * TW_METHOD_COUNT];
    const uint32_t n = s->point_count < 64 * TW_METHOD_COUNT ? s->point_count
                                                              : 64 * TW_METHOD_COUNT;
    for (uint32_t k = 0; k < n; k++) {
        uint32_t j = k;
        for (; j > 0 && s->points[order[j - 1]].cpu_ms > s->points[k].cpu_ms; j--)
            order[j] = order[j - 1];
        order[j] = k;
    }
    for (int file = 0; file < 3; file++) {
        struct tw_outfile o;
        int rc = open_in(&o, run->dir, names[file], err, err_size);
        if (rc)
            return rc;
        tw_outfile_printf(&o, "# %s of the sweep of %s, by mean CPU time per frame\n"
                              "method value mean_cpu_ms missed_per_frame depth_errors_per_frame "
                              "conservative front front_depth speedup\n", what[file], s->param);
        for (uint32_t k = 0; k < n; k++) {
            const struct tw_pareto_point *p = &s->points[order[k]];
            if ((file == 1 && !p->front) || (file == 2 && !p->front_depth))
                continue;
            tw_outfile_printf(&o, "%s %g %.3f %.3f %.3f %d %d %d %.3f\n", tw_method_name(p->method),
                              p->value, p->cpu_ms, p->missed_per_frame, p->depth_errors_per_frame,
                              p->conservative, p->front, p->front_depth, p->speedup);
        }
        if ((rc = tw_outfile_commit(&o, err, err_size)))
            return rc;
    }
    return TW_OK;
}

/* A gnuplot single-quoted string: '' stands for a quote; no control
 * characters. */
static void put_string(struct tw_outfile *o, const char *s)
{
    tw_outfile_printf(o, "'");
    for (; *s; s++) {
        const char c = (unsigned char)*s < 0x20 || *s == 0x7f ? '?' : *s;
        if (c == '\'')
            tw_outfile_printf(o, "''");
        else
            tw_outfile_printf(o, "%c", c);
    }
    tw_outfile_printf(o, "'");
}

/* chart-pareto.png needs a sweep whose accuracy was measured. */
static int pareto_drawn(const struct tw_chart_run *run)
{
    return run->sweep && run->sweep->points && run->sweep->point_count > 0 && run->verified;
}

static int write_run(const struct tw_chart_run *run, const uint32_t *order, char *err,
                     size_t err_size)
{
    struct tw_outfile o;
    int rc = open_in(&o, run->dir, DATA "/run.gp", err, err_size);
    if (rc)
        return rc;
    char title[800];
    snprintf(title, sizeof(title), "tileset %s, path %s, %ux%u", run->tileset, run->path,
             run->width, run->height);
    tw_outfile_printf(&o, "# What the run was, for charts.gp (written by tileworld)\nrun_title = ");
    put_string(&o, title);
    tw_outfile_printf(&o, "\nmethods = '");
    uint32_t frames = 0;
    bool same_frames = true;
    for (uint32_t k = 0; k < run->method_count; k++) {
        const struct tw_method_figures *fg = &run->figures[run->methods[k]];
        same_frames &= k == 0 || fg->frames == frames;
        frames = fg->frames;
        tw_outfile_printf(&o, "%s%s", k ? " " : "", tw_method_name(run->methods[k]));
    }
    tw_outfile_printf(&o, "'\n# 0: the methods ran different numbers of frames\n"
                          "frames_per_method = %u\n"
                          "# 1: --verify measured missed pixels and overdraw\nverified = %d\n",
                      same_frames ? frames : 0, run->verified ? 1 : 0);
    const struct tw_chart_sweep *s = run->sweep;
    tw_outfile_printf(&o, "# the swept parameter ('': no sweep), its values, and the methods\n"
                          "# whose drawing it does not change\nsweep_param = ");
    put_string(&o, s ? s->param : "");
    tw_outfile_printf(&o, "\nsweep_values = '");
    for (uint32_t k = 0; s && k < s->count; k++)
        tw_outfile_printf(&o, "%s%g", k ? " " : "", s->values[order[k]]);
    tw_outfile_printf(&o, "'\nsweep_unaffected = '");
    bool first = true;
    for (uint32_t k = 0; s && k < run->method_count; k++) {
        if (!unaffected(s, run->methods[k]))
            continue;
        tw_outfile_printf(&o, "%s%s", first ? "" : " ", tw_method_name(run->methods[k]));
        first = false;
    }
    tw_outfile_printf(&o, "'\n# 1: chart-data/pareto*.dat hold the sweep's speed against "
                          "accuracy (--verify)\npareto = %d\n", pareto_drawn(run));
    tw_outfile_printf(&o, "# 1: bench --split filled frames-*.dat's set_* columns\nsplit = %d\n",
                      run->split ? 1 : 0);
    return tw_outfile_commit(&o, err, err_size);
}

/* ---- gnuplot ---------------------------------------------------------------------- */

/* Gives each chart gnuplot drew (.chart-NAME.png.tmp) its name, or with
 * keep false removes them. Returns how many were renamed, or -1 with err. */
static int finish_charts(const char *dir, bool keep, char *err, size_t err_size)
{
    DIR *d = opendir(dir);
    if (!d) {
        snprintf(err, err_size, "%s: cannot read the folder: %s", dir, strerror(errno));
        return -1;
    }
    int renamed = 0;
    for (struct dirent *e; (e = readdir(d));) {
        const size_t n = strlen(e->d_name);
        if (strncmp(e->d_name, ".chart-", 7) != 0 || n < 15 ||
            strcmp(e->d_name + n - 8, ".png.tmp") != 0)
            continue;
        char tmp[TW_OUTFILE_PATH], final[TW_OUTFILE_PATH];
        snprintf(tmp, sizeof(tmp), "%s/%s", dir, e->d_name);
        snprintf(final, sizeof(final), "%s/%.*s", dir, (int)(n - 5), e->d_name + 1);
        if (!keep) {
            unlink(tmp);
        } else if (rename(tmp, final) != 0) {
            snprintf(err, err_size, "%s: cannot write: %s", final, strerror(errno));
            renamed = -1;
            break;
        } else {
            renamed++;
        }
    }
    closedir(d);
    return renamed;
}

/* The last line of gnuplot.log that says something (gnuplot's error, with
 * its script line, comes last). */
static void last_line(const char *file, char *out, size_t size)
{
    out[0] = '\0';
    FILE *f = fopen(file, "r");
    if (!f)
        return;
    char line[512];
    while (fgets(line, sizeof(line), f)) {
        size_t n = strcspn(line, "\r\n");
        line[n] = '\0';
        if (strspn(line, " \t^") < n)
            snprintf(out, size, "%s", line);
    }
    fclose(f);
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

/* Runs `gnuplot -e "cd 'DIR'; tw_temporaries = 1" charts.gp`, its output in
 * DIR/gnuplot.log. Returns TW_OK, TW_CHARTS_NOT_DRAWN or a negative error. */
int tw_charts_run_gnuplot(const char *dir, char *err, size_t err_size)
{
    char log_file[TW_OUTFILE_PATH];
    snprintf(log_file, sizeof(log_file), "%s/gnuplot.log", dir);
    struct tw_outfile log;
    int rc = tw_outfile_open(&log, log_file, err, err_size);
    if (rc)
        return rc;
    /* gnuplot's own quoting: '' inside a single-quoted string. */
    char command[2 * TW_OUTFILE_PATH + 64];
    size_t n = (size_t)snprintf(command, sizeof(command), "cd '");
    for (const char *c = dir; *c && n + 40 < sizeof(command); c++) {
        if (*c == '\'')
            command[n++] = '\'';
        command[n++] = *c;
    }
    snprintf(command + n, sizeof(command) - n, "'; tw_temporaries = 1");
    char *const argv[] = {"gnuplot", "-e", command, "charts.gp", NULL};

    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_adddup2(&actions, fileno(log.f), STDOUT_FILENO);
    posix_spawn_file_actions_adddup2(&actions, fileno(log.f), STDERR_FILENO);
    pid_t pid = 0;
    const int spawn_err = posix_spawnp(&pid, "gnuplot", &actions, NULL, argv, environ);
    posix_spawn_file_actions_destroy(&actions);
    if (spawn_err) {
        tw_outfile_discard(&log);
        if (spawn_err == ENOENT)
            snprintf(err, err_size, "%s: gnuplot is not installed (not found in PATH), so no charts "
                     "were drawn; charts.gp and chart-data/ are written: install gnuplot and run "
                     "`gnuplot charts.gp` there", dir);
        else
            snprintf(err, err_size, "%s: cannot run gnuplot: %s", dir, strerror(spawn_err));
        return TW_CHARTS_NOT_DRAWN;
    }

    /* Waited for with a deadline: a wedged gnuplot must not hold the run. */
    const double deadline = now_s() + TW_CHARTS_TIMEOUT_S;
    int status = 0;
    bool timed_out = false;
    for (;;) {
        const pid_t done = waitpid(pid, &status, WNOHANG);
        if (done == pid)
            break;
        if (done < 0 && errno != EINTR) {
            status = -1;
            break;
        }
        if (now_s() >= deadline) {
            kill(pid, SIGKILL);
            while (waitpid(pid, &status, 0) < 0 && errno == EINTR)
                ;
            timed_out = true;
            break;
        }
        const struct timespec pause = {0, 10 * 1000 * 1000};
        nanosleep(&pause, NULL);
    }
    if ((rc = tw_outfile_commit(&log, err, err_size)))
        return rc;
    const bool ok = !timed_out && status != -1 && WIFEXITED(status) && WEXITSTATUS(status) == 0;
    if (finish_charts(dir, ok, err, err_size) < 0 && ok)
        return TW_ERR_IO;
    if (ok)
        return TW_OK;
    char why[600];
    last_line(log_file, why, sizeof(why));
    if (timed_out)
        snprintf(err, err_size, "%s/charts.gp: gnuplot did not finish within %d s and was stopped; "
                 "no charts", dir, TW_CHARTS_TIMEOUT_S);
    else if (status != -1 && WIFSIGNALED(status))
        snprintf(err, err_size, "%s/charts.gp: gnuplot was killed by signal %d, no charts (see "
                 "gnuplot.log)", dir, WTERMSIG(status));
    else
        snprintf(err, err_size, "%s/charts.gp: gnuplot failed (exit status %d), no charts: %s", dir,
                 status == -1 ? -1 : WEXITSTATUS(status), *why ? why : "no message");
    return TW_CHARTS_NOT_DRAWN;
}

int tw_charts_write(const struct tw_chart_run *run, char *err, size_t err_size)
{
    uint32_t order[64] = {0};
    if (run->sweep && run->sweep->count > sizeof(order) / sizeof(order[0])) {
        snprintf(err, err_size, "%s: more than 64 sweep values to chart", run->dir);
        return TW_ERR_LIMIT;
    }
    if (run->sweep)
        sort_values(run->sweep, order);
    char file[TW_OUTFILE_PATH];
    snprintf(file, sizeof(file), "%s/charts.gp", run->dir);
    int rc = write_methods(run, err, err_size);
    if (!rc && run->sweep)
        rc = write_sweep(run, order, err, err_size);
    if (!rc && pareto_drawn(run))
        rc = write_pareto(run, err, err_size);
    if (!rc)
        rc = write_run(run, order, err, err_size);
    if (!rc)
        rc = tw_outfile_write_all(file, TW_CHARTS_GP, strlen(TW_CHARTS_GP), err, err_size);
    return rc ? rc : tw_charts_run_gnuplot(run->dir, err, err_size);
}
