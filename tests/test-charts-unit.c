/* The parts of the bench charts (tools/tileworld/charts.h) that need no GL:
 * labels placed apart (coincident points, a crowded area, edges, obstacles,
 * leader lines), the PNG check on whole, truncated and corrupted files,
 * gnuplot's charts checked before they are named (a fake gnuplot that
 * exits 0 having written a short chart; on a full tmpfs when mounting is
 * permitted), and the data a GPU run writes (GPU time primary, unknown GPU
 * time left out, CPU time where none came back, the Pareto front by GPU
 * time), drawn by the real gnuplot where there is one. */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tools/tileworld/charts.h"
#include "tests/check.h"

/* ---- labels ------------------------------------------------------------------------- */

static struct tw_chart_box box_of(const struct tw_chart_label *l)
{
    return (struct tw_chart_box){l->centre_x - 0.5 * l->width, l->centre_y - 0.5 * l->height,
                                 l->centre_x + 0.5 * l->width, l->centre_y + 0.5 * l->height};
}

/* Whether two boxes share an area (touching edges do not). */
static bool overlap(struct tw_chart_box a, struct tw_chart_box b)
{
    const double eps = 1e-9;
    return a.x0 < b.x1 - eps && b.x0 < a.x1 - eps && a.y0 < b.y1 - eps && b.y0 < a.y1 - eps;
}

static bool inside(struct tw_chart_box a, struct tw_chart_box area)
{
    const double eps = 1e-9;
    return a.x0 >= area.x0 - eps && a.x1 <= area.x1 + eps && a.y0 >= area.y0 - eps &&
           a.y1 <= area.y1 + eps;
}

/* Whether the segment from (x0, y0) to (x1, y1) passes through the inside
 * of b (sampled: 1000 steps). */
static bool crosses(double x0, double y0, double x1, double y1, struct tw_chart_box b)
{
    const struct tw_chart_box in = {b.x0 + 0.01, b.y0 + 0.01, b.x1 - 0.01, b.y1 - 0.01};
    for (int k = 0; k <= 1000; k++) {
        const double t = k / 1000.0, x = x0 + t * (x1 - x0), y = y0 + t * (y1 - y0);
        if (x > in.x0 && x < in.x1 && y > in.y0 && y < in.y1)
            return true;
    }
    return false;
}

/* Every label inside area, over no other label and no obstacle; with
 * clear_leaders, no leader line through another label either. */
static void check_apart(const char *what, const struct tw_chart_label *l, uint32_t n,
                        const struct tw_chart_box *obstacles, uint32_t obstacle_count,
                        struct tw_chart_box area, bool clear_leaders)
{
    for (uint32_t k = 0; k < n; k++) {
        const struct tw_chart_box b = box_of(&l[k]);
        CHECK_MSG(inside(b, area), "%s: label %u at %.1f,%.1f is outside the area", what, k,
                  l[k].centre_x, l[k].centre_y);
        CHECK_MSG(!l[k].overlaps, "%s: label %u says it overlaps", what, k);
        for (uint32_t o = 0; o < obstacle_count; o++)
            CHECK_MSG(!overlap(b, obstacles[o]), "%s: label %u is over obstacle %u", what, k, o);
        double ax, ay;
        tw_charts_label_anchor(&l[k], &ax, &ay);
        for (uint32_t j = 0; j < n; j++) {
            if (j == k)
                continue;
            CHECK_MSG(j < k || !overlap(b, box_of(&l[j])), "%s: labels %u and %u overlap", what, k,
                      j);
            CHECK_MSG(!clear_leaders || !l[k].moved || !crosses(l[k].x, l[k].y, ax, ay, box_of(&l[j])),
                      "%s: label %u's leader line crosses label %u", what, k, j);
        }
    }
}

static void test_coincident(void)
{
    enum { N = 12 };
    struct tw_chart_label l[N], again[N];
    memset(l, 0, sizeof(l));
    for (uint32_t k = 0; k < N; k++)
        l[k] = (struct tw_chart_label){.x = 300, .y = 200, .width = 40 + 8 * k, .height = 14};
    memcpy(again, l, sizeof(l));
    /* The marker of the point they all label. */
    const struct tw_chart_box marker = {292, 192, 308, 208};
    const struct tw_chart_box area = {0, 0, 600, 400};
    CHECK(tw_charts_place_labels(l, N, &marker, 1, 10, area) == 0);
    /* Twelve labels around one point: some leader lines must cross a label
     * beside it. */
    check_apart("coincident", l, N, &marker, 1, area, false);
    /* The first beside its point, to the right; the rest, which cannot all
     * be beside it, moved and joined to it. */
    CHECK(!l[0].moved && l[0].centre_x > 300 && fabs(l[0].centre_y - 200) < 1e-9);
    uint32_t moved = 0;
    for (uint32_t k = 0; k < N; k++) {
        moved += l[k].moved;
        double ax, ay;
        tw_charts_label_anchor(&l[k], &ax, &ay);
        /* A leader line ends on its label's border. */
        const double dx = fabs(ax - l[k].centre_x), dy = fabs(ay - l[k].centre_y);
        CHECK_MSG(dx <= 0.5 * l[k].width + 1e-6 && dy <= 0.5 * l[k].height + 1e-6 &&
                      (fabs(dx - 0.5 * l[k].width) < 1e-6 || fabs(dy - 0.5 * l[k].height) < 1e-6),
                  "label %u: anchor %.2f,%.2f is not on its border", k, ax, ay);
    }
    CHECK_MSG(moved >= N - 8 && moved < N, "%u of %u moved", moved, (unsigned)N);
    /* The same places every time. */
    CHECK(tw_charts_place_labels(again, N, &marker, 1, 10, area) == 0);
    CHECK(memcmp(l, again, sizeof(l)) == 0);
    /* Four: all beside it or joined by lines that cross no label. */
    CHECK(tw_charts_place_labels(again, 4, &marker, 1, 10, area) == 0);
    check_apart("four coincident", again, 4, &marker, 1, area, true);
}

/* Coincident points in pairs and a row of near neighbours, as a sweep's
 * values that change nothing draw them. */
static void test_neighbours(void)
{
    enum { N = 20 };
    struct tw_chart_label l[N];
    struct tw_chart_box markers[N];
    memset(l, 0, sizeof(l));
    for (uint32_t k = 0; k < N; k++) {
        const double x = 60 + 3 * (k / 2), y = 380;
        l[k] = (struct tw_chart_label){.x = x, .y = y, .width = 90, .height = 13};
        markers[k] = (struct tw_chart_box){x - 6, y - 6, x + 6, y + 6};
    }
    const struct tw_chart_box area = {50, 100, 550, 395};
    CHECK(tw_charts_place_labels(l, N, markers, N, 8, area) == 0);
    check_apart("neighbours", l, N, markers, N, area, false);
}

static void test_crowded_edges_obstacles(void)
{
    /* No room for six labels: they are placed where they overlap least,
     * and say so. */
    struct tw_chart_label l[6];
    memset(l, 0, sizeof(l));
    for (int k = 0; k < 6; k++)
        l[k] = (struct tw_chart_label){.x = 60, .y = 15, .width = 100, .height = 14};
    const struct tw_chart_box small = {0, 0, 120, 30};
    const uint32_t bad = tw_charts_place_labels(l, 6, NULL, 0, 5, small);
    uint32_t flagged = 0;
    for (int k = 0; k < 6; k++)
        flagged += l[k].overlaps;
    CHECK_MSG(bad > 0 && bad == flagged, "%u overlapping, %u flagged", bad, flagged);
    /* A point in a corner: its label stays inside, beside it. */
    struct tw_chart_label corner = {.x = 3, .y = 3, .width = 50, .height = 12};
    const struct tw_chart_box area = {0, 0, 200, 200};
    CHECK(tw_charts_place_labels(&corner, 1, NULL, 0, 6, area) == 0);
    CHECK(inside(box_of(&corner), area) && !corner.moved);
    /* An obstacle to the right: the label goes above instead, still beside. */
    struct tw_chart_label blocked = {.x = 100, .y = 100, .width = 40, .height = 12};
    const struct tw_chart_box note = {104, 95, 190, 105};
    CHECK(tw_charts_place_labels(&blocked, 1, &note, 1, 6, area) == 0);
    CHECK(!blocked.moved && blocked.centre_y < 100 && !overlap(box_of(&blocked), note));
}

/* ---- the PNG check ------------------------------------------------------------------- */

static char *read_file(const char *file, size_t *size)
{
    FILE *f = fopen(file, "rb");
    if (!f)
        return NULL;
    static char data[1 << 20];
    *size = fread(data, 1, sizeof(data) - 1, f);
    data[*size] = '\0';
    fclose(f);
    return data;
}

static void write_file(const char *file, const void *data, size_t size)
{
    FILE *f = fopen(file, "wb");
    CHECK(f != NULL);
    if (f) {
        CHECK(fwrite(data, 1, size, f) == size);
        fclose(f);
    }
}

/* A whole PNG written by the program's own writer: what gnuplot's are. */
static void make_png(const char *file)
{
    unsigned char rgb[64 * 32 * 3];
    for (size_t k = 0; k < sizeof(rgb); k++)
        rgb[k] = (unsigned char)(k * 7 + k / 97);
    char err[512];
    CHECK_MSG(tw_outfile_write_png(file, rgb, 64, 32, err, sizeof(err)) == 0, "%s", err);
}

/* file fails the check with a message naming it and saying want. */
static void expect_refused(const char *file, const char *want)
{
    char err[1024];
    const int rc = tw_charts_check_png(file, err, sizeof(err));
    CHECK_MSG(rc == TW_ERR_FORMAT, "%s: %d", file, rc);
    CHECK_MSG(rc == TW_OK || (strstr(err, file) == err && strstr(err, want)),
              "%s: '%s' does not say '%s'", file, err, want);
}

static void test_png(const char *dir)
{
    char good[256], bad[256], err[1024];
    snprintf(good, sizeof(good), "%s/good.png", dir);
    snprintf(bad, sizeof(bad), "%s/bad.png", dir);
    make_png(good);
    CHECK_MSG(tw_charts_check_png(good, err, sizeof(err)) == TW_OK, "%s", err);
    size_t size = 0;
    char *data = read_file(good, &size);
    CHECK(data && size > 100);
    if (!data)
        return;
    char *copy = malloc(size + 16);
    /* Cut anywhere: empty, inside the signature, after it, inside IHDR,
     * inside IDAT, before IEND, inside IEND. */
    const size_t cuts[] = {0, 5, 8, 20, 45, size / 2, size - 12, size - 1};
    const char *const says[] = {"empty (0 bytes)", "not a PNG", "truncated", "truncated",
                                "truncated", "truncated", "truncated", "truncated"};
    for (size_t k = 0; k < sizeof(cuts) / sizeof(cuts[0]); k++) {
        write_file(bad, data, cuts[k]);
        expect_refused(bad, says[k]);
    }
    /* A byte changed inside the image data. */
    memcpy(copy, data, size);
    copy[size / 2] ^= 0x40;
    write_file(bad, copy, size);
    expect_refused(bad, "bad CRC");
    /* Something after IEND. */
    memcpy(copy, data, size);
    memcpy(copy + size, "garbage", 7);
    write_file(bad, copy, size + 7);
    expect_refused(bad, "7 bytes after its IEND chunk");
    /* Not there. */
    unlink(bad);
    CHECK(tw_charts_check_png(bad, err, sizeof(err)) == TW_ERR_IO && strstr(err, "cannot read"));
    free(copy);
}

/* ---- gnuplot's charts checked before they are named ------------------------------------ */

static bool exists(const char *dir, const char *name)
{
    char file[512];
    snprintf(file, sizeof(file), "%s/%s", dir, name);
    return access(file, F_OK) == 0;
}

/* A fake gnuplot in bin: runs script (in sh, with GOOD a whole PNG and RUN
 * the run's folder) and exits with its status. */
static void fake_gnuplot(const char *bin, const char *script)
{
    char file[512];
    snprintf(file, sizeof(file), "%s/gnuplot", bin);
    FILE *f = fopen(file, "w");
    CHECK(f != NULL);
    if (!f)
        return;
    fprintf(f, "#!/bin/sh\n%s\n", script);
    fclose(f);
    chmod(file, 0755);
}

static void test_runner(const char *dir, const char *system_path)
{
    char bin[256], run[256], good[256], path[1400], err[2048];
    snprintf(bin, sizeof(bin), "%s/bin", dir);
    snprintf(run, sizeof(run), "%s/run", dir);
    snprintf(good, sizeof(good), "%s/good.png", dir);
    CHECK(mkdir(bin, 0755) == 0 && mkdir(run, 0755) == 0);
    snprintf(path, sizeof(path), "%s:%s", bin, system_path);
    setenv("PATH", path, 1);
    setenv("GOOD", good, 1);
    setenv("RUN", run, 1);

    /* gnuplot exits 0 having written one chart short: that one is refused
     * and removed, the whole one named, the run fails. */
    fake_gnuplot(bin, "cp \"$GOOD\" \"$RUN/.chart-a-good.png.tmp\"\n"
                      "head -c 100 \"$GOOD\" >\"$RUN/.chart-b-short.png.tmp\"\n"
                      ": >\"$RUN/.chart-c-empty.png.tmp\"\nexit 0");
    int rc = tw_charts_run_gnuplot(run, err, sizeof(err));
    CHECK_MSG(rc == TW_ERR_IO, "%d: %s", rc, err);
    CHECK_MSG(strstr(err, "/chart-b-short.png: gnuplot did not write it whole: truncated"),
              "%s", err);
    CHECK(exists(run, "chart-a-good.png") && !exists(run, "chart-b-short.png") &&
          !exists(run, "chart-c-empty.png") && !exists(run, ".chart-b-short.png.tmp") &&
          !exists(run, ".chart-c-empty.png.tmp") && exists(run, "gnuplot.log"));
    char named[512];
    snprintf(named, sizeof(named), "%s/chart-a-good.png", run);
    unlink(named);

    /* Whole charts are named. */
    fake_gnuplot(bin, "cp \"$GOOD\" \"$RUN/.chart-a-good.png.tmp\"\nexit 0");
    rc = tw_charts_run_gnuplot(run, err, sizeof(err));
    CHECK_MSG(rc == TW_OK, "%d: %s", rc, err);
    CHECK(exists(run, "chart-a-good.png") && !exists(run, ".chart-a-good.png.tmp"));
    unlink(named);

    /* gnuplot fails with room on the disk: a warning, no chart kept. */
    fake_gnuplot(bin, "cp \"$GOOD\" \"$RUN/.chart-a-good.png.tmp\"\necho 'line 3: broke' >&2\n"
                      "exit 1");
    rc = tw_charts_run_gnuplot(run, err, sizeof(err));
    CHECK_MSG(rc == TW_CHARTS_NOT_DRAWN && strstr(err, "gnuplot failed (exit status 1)") &&
                  strstr(err, "line 3: broke"), "%d: %s", rc, err);
    CHECK(!exists(run, "chart-a-good.png") && !exists(run, ".chart-a-good.png.tmp"));

    /* A full disk: a tmpfs of 128 KiB, filled; gnuplot exits 0 with a
     * chart it could not write whole. Needs mount (root): skipped where it
     * is not permitted. */
    char full[256], command[1024];
    snprintf(full, sizeof(full), "%s/full", dir);
    CHECK(mkdir(full, 0755) == 0);
    snprintf(command, sizeof(command), "mount -t tmpfs -o size=128k tmpfs '%s' 2>/dev/null", full);
    if (system(command) != 0) {
        printf("full disk: skipped (cannot mount a tmpfs here)\n");
    } else {
        setenv("RUN", full, 1);
        /* Filled to the last block. */
        snprintf(command, sizeof(command), "head -c 200000 /dev/zero >'%s/filler' 2>/dev/null",
                 full);
        if (system(command) == 0)
            CHECK(!"the filler fitted in a tmpfs of 128 KiB");
        fake_gnuplot(bin, "cp \"$GOOD\" \"$RUN/.chart-full.png.tmp\" 2>/dev/null\nexit 0");
        rc = tw_charts_run_gnuplot(full, err, sizeof(err));
        CHECK_MSG(rc == TW_ERR_IO && strstr(err, "/chart-full.png: cannot write: No space left on "
                                                 "device (gnuplot left it "), "%d: %s", rc, err);
        CHECK(!exists(full, "chart-full.png") && !exists(full, ".chart-full.png.tmp") &&
              !exists(full, ".tw-space-probe.tmp"));
        /* gnuplot that fails on the full disk: an error, not a warning. */
        fake_gnuplot(bin, "echo 'cannot open file' >&2\nexit 1");
        rc = tw_charts_run_gnuplot(full, err, sizeof(err));
        CHECK_MSG(rc == TW_ERR_IO && (strstr(err, "No space left on device")), "%d: %s", rc, err);
        snprintf(command, sizeof(command), "umount '%s'", full);
        CHECK(system(command) == 0);
        printf("full disk: checked on a tmpfs\n");
    }
    rmdir(full);
    setenv("PATH", system_path, 1);
}

/* ---- a GPU run's data ------------------------------------------------------------------ */

static void set_figures(struct tw_method_figures *fg, double wall, double cpu, double gpu,
                        uint32_t gpu_frames, uint64_t missed, double overdraw)
{
    memset(fg, 0, sizeof(*fg));
    fg->used = true;
    fg->frames = 4;
    fg->mean_ms = fg->median_ms = wall;
    fg->mean_cpu_ms = fg->median_cpu_ms = cpu;
    fg->mean_gpu_ms = gpu_frames ? gpu : -1.0;
    fg->gpu_frames = gpu_frames;
    fg->mean_triangles = 1000.0 * cpu;
    fg->missed_pixels_total = missed;
    fg->mean_overdraw_triangles = overdraw;
}

/* frames-METHOD.dat as the report writes it (the columns charts.gp reads). */
static void write_frames(const char *run, const char *method, const double *gpu)
{
    char file[512];
    snprintf(file, sizeof(file), "%s/chart-data/frames-%s.dat", run, method);
    FILE *f = fopen(file, "w");
    CHECK(f != NULL);
    if (!f)
        return;
    fprintf(f, "# %s\nframe ms_frame triangles cpu_ms missed_pixels overdraw_triangles set_cpu_ms "
               "gpu_ms gpu_ms_id\n", method);
    for (int k = 0; k < 4; k++)
        fprintf(f, "%d %.3f %d %.3f 0 0 0 %.3f 0\n", k, 20.0 + k, 1000 + k, 10.0 + k, gpu[k]);
    fclose(f);
}

static bool has(const char *run, const char *name, const char *text)
{
    char file[512];
    snprintf(file, sizeof(file), "%s/%s", run, name);
    size_t size = 0;
    const char *data = read_file(file, &size);
    return data && strstr(data, text);
}

static void test_gpu_data(const char *dir, const char *system_path)
{
    char run_dir[256], data[300], err[2048];
    snprintf(run_dir, sizeof(run_dir), "%s/gpu", dir);
    snprintf(data, sizeof(data), "%s/chart-data", run_dir);
    CHECK(mkdir(run_dir, 0755) == 0 && mkdir(data, 0755) == 0);
    const enum tw_method methods[3] = {TW_METHOD_VFC, TW_METHOD_CHC, TW_METHOD_TILEQUERY_CHC};
    static const double vfc_gpu[4] = {30, 31, -1, 29}, chc_gpu[4] = {5, -1, -1, 5},
                        tq_gpu[4] = {6, 6, 6, 6};
    write_frames(run_dir, "vfc", vfc_gpu);
    write_frames(run_dir, "chc", chc_gpu);
    write_frames(run_dir, "tilequery+chc", tq_gpu);
    struct tw_method_figures figures[TW_METHOD_ALL];
    memset(figures, 0, sizeof(figures));
    /* chc and tilequery+chc coincide in CPU time and accuracy: their labels
     * must be placed apart. */
    set_figures(&figures[TW_METHOD_VFC], 50, 40, 30, 3, 0, 5e5);
    set_figures(&figures[TW_METHOD_CHC], 20, 10, 5, 2, 0, 2e4);
    set_figures(&figures[TW_METHOD_TILEQUERY_CHC], 21, 10, 6, 4, 0, 2e4);

    /* A sweep of T over two values; the fronts by CPU time (pareto.h) put
     * chc T=4 on it, by GPU time tilequery+chc T=4. */
    static const double values[2] = {4, 0};
    struct tw_method_figures (*sweep)[TW_METHOD_ALL] = calloc(2, sizeof(*sweep));
    bool (*conservative)[TW_METHOD_ALL] = calloc(2, sizeof(*conservative));
    CHECK(sweep && conservative);
    if (!sweep || !conservative)
        return;
    for (int k = 0; k < 2; k++) {
        set_figures(&sweep[k][TW_METHOD_VFC], 50, 40, 30, 3, 0, 5e5);
        conservative[k][TW_METHOD_VFC] = true;
    }
    set_figures(&sweep[0][TW_METHOD_CHC], 15, 7, 9, 4, 40, 1e4);
    set_figures(&sweep[0][TW_METHOD_TILEQUERY_CHC], 15, 8, 4, 4, 40, 1e4);
    set_figures(&sweep[1][TW_METHOD_CHC], 20, 10, 5, 4, 0, 2e4);
    set_figures(&sweep[1][TW_METHOD_TILEQUERY_CHC], 21, 10, 6, 4, 0, 2e4);
    conservative[1][TW_METHOD_CHC] = conservative[1][TW_METHOD_TILEQUERY_CHC] = true;
    struct tw_pareto_point points[6];
    tw_pareto_points(values, 2, (const struct tw_method_figures(*)[TW_METHOD_ALL])sweep,
                     (const bool(*)[TW_METHOD_ALL])conservative, methods, 3, figures, 1, points);
    const struct tw_chart_sweep chart_sweep = {
        "T", 2, values, (const struct tw_method_figures(*)[TW_METHOD_ALL])sweep, points, 6,
    };
    struct tw_chart_run run = {
        .dir = run_dir, .tileset = "city", .path = "street", .width = 160, .height = 90,
        .verified = true, .methods = methods, .method_count = 3, .figures = figures,
        .sweep = &chart_sweep, .time = TW_CHART_TIME_GPU, .context = "egl-device",
    };
    /* No gnuplot: the data and script are written, and a warning. */
    char empty[300];
    snprintf(empty, sizeof(empty), "%s/empty-bin", dir);
    CHECK(mkdir(empty, 0755) == 0);
    setenv("PATH", empty, 1);
    int rc = tw_charts_write(&run, err, sizeof(err));
    CHECK_MSG(rc == TW_CHARTS_NOT_DRAWN && strstr(err, "gnuplot is not installed"), "%d: %s", rc,
              err);
    CHECK(has(run_dir, "chart-data/run.gp", "\ntime = 'gpu'\nframe_time_column = 'gpu_ms'\n"
                                            "mean_time_column = 'mean_gpu_ms'\n"
                                            "time_name = 'GPU time'\n"
                                            "time_note = 'egl-device, frames whose GPU time did "
                                            "not come back left out'\n"));
    CHECK(has(run_dir, "chart-data/run.gp", "\narray mean_time[3] = [30, 5, 6]\n"
                                            "array mean_wall[3] = [50, 20, 21]\n"
                                            "array time_frames[3] = [3, 2, 4]\n"));
    CHECK(has(run_dir, "chart-data/methods.dat", " mean_gpu_ms gpu_frames\n"));
    CHECK(has(run_dir, "chart-data/methods.dat", "\nchc 4 20.000 ") &&
          has(run_dir, "chart-data/methods.dat", " 5.000 2\n"));
    CHECK(has(run_dir, "chart-data/sweep-chc.dat", "\n0 4 20.000 ") &&
          has(run_dir, "chart-data/sweep-chc.dat", "\n4 4 15.000 "));
    /* The front by GPU time: tilequery+chc T=4 (4 ms), not chc T=4 (9 ms
     * GPU, though 7 ms CPU). */
    CHECK(has(run_dir, "chart-data/pareto-front.dat", "\ntilequery+chc 4 8.000 ") &&
          !has(run_dir, "chart-data/pareto-front.dat", "\nchc 4 "));
    CHECK(has(run_dir, "chart-data/pareto.dat", "\ntilequery+chc 4 8.000 10.000 0.000 0 1 1 "));
    /* The coincident points' labels: both beside or joined, never one over
     * the other (the placement itself is checked above). */
    CHECK(has(run_dir, "chart-data/labels-speed-accuracy-1.dat", "\nchc 1 5 1 ") &&
          has(run_dir, "chart-data/labels-speed-accuracy-1.dat", "\"tilequery+chc T=0\""));
    CHECK(has(run_dir, "chart-data/labels-pareto-1.dat", "\"tilequery+chc T=4\""));

    /* Asked for GPU time and none came back: CPU time, and the charts say so. */
    struct tw_method_figures cpu_only[TW_METHOD_ALL];
    memcpy(cpu_only, figures, sizeof(cpu_only));
    for (int m = 0; m < TW_METHOD_ALL; m++)
        cpu_only[m].gpu_frames = 0;
    run.figures = cpu_only;
    run.sweep = NULL;
    rc = tw_charts_write(&run, err, sizeof(err));
    CHECK(rc == TW_CHARTS_NOT_DRAWN);
    CHECK(has(run_dir, "chart-data/run.gp", "\ntime = 'cpu'\nframe_time_column = 'cpu_ms'\n") &&
          has(run_dir, "chart-data/run.gp", "time_note = 'the process''s, all threads (no GPU "
                                            "time came back)'\n") &&
          has(run_dir, "chart-data/run.gp", "\narray mean_time[3] = [40, 10, 10]\n"));
    CHECK(has(run_dir, "chart-data/methods.dat", " NaN 0\n"));
    /* The default, a software renderer's: CPU time. */
    run.figures = figures;
    run.time = TW_CHART_TIME_CPU;
    rc = tw_charts_write(&run, err, sizeof(err));
    CHECK(has(run_dir, "chart-data/run.gp", "\ntime = 'cpu'\n") &&
          has(run_dir, "chart-data/run.gp", "time_note = 'the process''s, all threads'\n"));

    /* The real gnuplot, where there is one, draws the GPU run's charts
     * whole, with nothing to say. */
    setenv("PATH", system_path, 1);
    if (system("command -v gnuplot >/dev/null 2>&1") != 0) {
        printf("gnuplot: skipped (not installed)\n");
    } else {
        run.sweep = &chart_sweep;
        run.time = TW_CHART_TIME_GPU;
        rc = tw_charts_write(&run, err, sizeof(err));
        CHECK_MSG(rc == TW_OK, "%d: %s", rc, err);
        static const char *const charts[] = {
            "chart-frame-time.png", "chart-frame-time-wall.png", "chart-triangles.png",
            "chart-speed-accuracy.png", "chart-sweep.png", "chart-sweep-wall.png",
            "chart-pareto.png",
        };
        for (size_t k = 0; k < sizeof(charts) / sizeof(charts[0]); k++) {
            char file[512];
            snprintf(file, sizeof(file), "%s/%s", run_dir, charts[k]);
            CHECK_MSG(tw_charts_check_png(file, err, sizeof(err)) == TW_OK, "%s", err);
        }
        char log[512];
        snprintf(log, sizeof(log), "%s/gnuplot.log", run_dir);
        struct stat st;
        CHECK_MSG(stat(log, &st) == 0 && st.st_size == 0, "gnuplot.log: %s",
                  has(run_dir, "gnuplot.log", "") ? read_file(log, &(size_t){0}) : "missing");
    }
    free(conservative);
    free(sweep);
}

int main(void)
{
    test_coincident();
    test_neighbours();
    test_crowded_edges_obstacles();

    const char *path = getenv("PATH");
    char system_path[1024];
    snprintf(system_path, sizeof(system_path), "%s", path ? path : "/usr/bin:/bin");
    char dir[] = "/tmp/test-charts-unit-XXXXXX";
    CHECK(mkdtemp(dir) != NULL);
    test_png(dir);
    test_runner(dir, system_path);
    test_gpu_data(dir, system_path);
    char command[512];
    snprintf(command, sizeof(command), "rm -rf '%s'", dir);
    CHECK(system(command) == 0);
    return check_summary("test-charts-unit");
}
