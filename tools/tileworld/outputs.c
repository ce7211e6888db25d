/* Removing what an earlier run left in a folder, by known names only (outputs.h). */
#include "tools/tileworld/outputs.h"

#include <dirent.h>
#include <errno.h>
#include <stdbool.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "tileworld/runtime.h"
#include "tools/outfile.h"
#include "tools/tileworld/report.h"

enum folder { RUN_FOLDER, CHART_DATA, SCENARIO_FOLDER };

static const char *const run_files[] = {
    "frames.csv", "summary.json", "summary.md", "sweep.csv", "sweep.md", "scenarios.md",
    "scenarios.json", "charts.gp", "gnuplot.log", "memory.csv", NULL,
};

static bool ends_with(const char *s, size_t n, const char *end)
{
    const size_t m = strlen(end);
    return n >= m && memcmp(s + n - m, end, m) == 0;
}

static bool is_method(const char *s, size_t n)
{
    for (int m = 0; m < TW_METHOD_ALL; m++) {
        const char *name = tw_method_name((enum tw_method)m);
        if (strlen(name) == n && memcmp(s, name, n) == 0)
            return true;
    }
    return false;
}

/* frame-NNNNN.png or frame-NNNNN-METHOD.png (at least five digits). */
static bool is_frame_png(const char *s, size_t n)
{
    if (n < 14 || strncmp(s, "frame-", 6) != 0 || !ends_with(s, n, ".png"))
        return false;
    size_t k = 6;
    while (k < n && s[k] >= '0' && s[k] <= '9')
        k++;
    if (k - 6 < 5)
        return false;
    if (k == n - 4)
        return true;
    return s[k] == '-' && is_method(s + k + 1, n - 4 - k - 1);
}

/* A file of ours in a folder of that kind (name without a temporary's
 * dot and .tmp). */
static bool is_output_file(enum folder kind, const char *s, size_t n)
{
    if (kind == CHART_DATA)
        return ends_with(s, n, ".dat") || (n == 6 && memcmp(s, "run.gp", 6) == 0);
    for (const char *const *f = run_files; *f; f++)
        if (strlen(*f) == n && memcmp(s, *f, n) == 0)
            return true;
    return (n > 10 && strncmp(s, "chart-", 6) == 0 && ends_with(s, n, ".png")) ||
           is_frame_png(s, n);
}

/* A folder of ours inside a folder of that kind. */
static bool is_output_folder(enum folder kind, const char *s, enum folder *inner)
{
    static const char *const params[] = {
        "n_av", "b", "T", "cluster_triangles", "evict_after", "view_distance", "neighbours",
        "budget", NULL,
    };
    if (kind == CHART_DATA)
        return false;
    *inner = RUN_FOLDER;
    if (kind == SCENARIO_FOLDER && strcmp(s, "far") == 0)
        return true;
    if (strcmp(s, TW_REPORT_CHART_DATA) == 0) {
        *inner = CHART_DATA;
        return true;
    }
    if (strncmp(s, "scenario-", 9) == 0 && s[9] != '\0') {
        *inner = SCENARIO_FOLDER;
        return true;
    }
    if (strncmp(s, "sweep-", 6) == 0)
        for (const char *const *p = params; *p; p++)
            if (strncmp(s + 6, *p, strlen(*p)) == 0 && s[6 + strlen(*p)] == '-')
                return true;
    return false;
}

static int remove_in(const char *dir, enum folder kind, char *err, size_t err_size)
{
    DIR *d = opendir(dir);
    if (!d) {
        if (errno == ENOENT || errno == ENOTDIR)
            return TW_OK;   /* nothing left; a file where the folder goes is found later */
        snprintf(err, err_size, "%s: cannot read the folder: %s", dir, strerror(errno));
        return TW_ERR_IO;
    }
    int rc = TW_OK;
    for (struct dirent *e; rc == TW_OK && (e = readdir(d));) {
        const char *s = e->d_name;
        size_t n = strlen(s);
        char path[TW_OUTFILE_PATH];
        const int len = snprintf(path, sizeof(path), "%s/%s", dir, s);
        if (len < 0 || (size_t)len >= sizeof(path))
            continue;
        enum folder inner;
        if (strcmp(s, ".") != 0 && strcmp(s, "..") != 0 && is_output_folder(kind, s, &inner)) {
            rc = remove_in(path, inner, err, err_size);
            if (rc == TW_OK && rmdir(path) != 0 && errno != ENOTEMPTY && errno != EEXIST &&
                errno != ENOTDIR && errno != ENOENT) {
                snprintf(err, err_size, "%s: cannot remove: %s", path, strerror(errno));
                rc = TW_ERR_IO;
            }
            continue;
        }
        const bool tmp = n > 5 && s[0] == '.' && ends_with(s, n, ".tmp");
        if (!is_output_file(kind, tmp ? s + 1 : s, tmp ? n - 5 : n))
            continue;
        if (unlink(path) != 0 && errno != ENOENT) {
            snprintf(err, err_size, "%s: cannot remove: %s", path, strerror(errno));
            rc = TW_ERR_IO;
        }
    }
    closedir(d);
    return rc;
}

int tw_outputs_remove_stale(const char *dir, char *err, size_t err_size)
{
    return remove_in(dir, RUN_FOLDER, err, err_size);
}
