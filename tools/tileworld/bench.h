/*
 * Runs of the tileworld command: one walk or bench over a path with one or
 * several methods (alternating frame by frame), parameter sweeps, and the
 * stability scenarios of DESIGN.md §11.
 *
 * Every run first removes what an earlier run left in its folder
 * (outputs.h), then writes each file whole or not at all (outfile.h): a
 * failed run leaves the complete files it wrote before the failure (frame
 * PNGs) and none of the summaries; a killed one, at most hidden .NAME.tmp
 * files besides.
 */
#ifndef TW_TOOLS_BENCH_H
#define TW_TOOLS_BENCH_H

#include "tools/progress.h"
#include "tools/tileworld/report.h"
#include "runtime/runtime-internal.h"
#include "tileworld/context.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

/* The most cars a run drives (--cars, a sweep of cars). */
#define TW_RUN_MAX_CARS 100000u

/* Called after every frame of every method (may be NULL). */
typedef void (*tw_run_frame_fn)(void *user, uint32_t frame_index, struct tw_world *w,
                                const struct tw_frame_stats *st);

struct tw_run {
    const struct tw_tileset *tileset;   /* borrowed; NULL with a provider */
    const struct tw_tile_provider *provider; /* borrowed: instead of tileset; NULL with one */
    const char *tileset_name;
    const struct tw_path *path;         /* borrowed */
    const char *path_name;
    struct tw_world_settings world;     /* tileset and get_proc are filled in by tw_run_execute */
    struct tw_world_tuning tuning;
    enum tw_method methods[TW_METHOD_ALL];
    uint32_t method_count;
    const char *out;                    /* output folder */
    uint32_t png_every;
    uint32_t fps;                       /* --fps: 0, frames as fast as they render; else a
                                           frame starts no sooner than 1 / fps s after the
                                           last one was due (a late frame restarts the pace) */
    uint32_t views;                     /* 2: a chase camera drawn as a viewport after every
                                           frame (its frames are not reported; the memory
                                           figures are the shared world's); 0, 1: one */
    /* Moving cars (--cars): with cars > 0 the world shows car_models
     * (borrowed) as its object_models, and cars of traffic (its streets and
     * seed; the count, the centre, the path's first cell, and the radius,
     * the view distance, are the run's) drive from before the first frame,
     * each moved to where it is at frame / 30 s before every frame. */
    uint32_t cars;                      /* 0..TW_RUN_MAX_CARS */
    /* The 3D Tiles provider behind the world (borrowed; NULL: none): its
     * counters go into summary.json. */
    const struct tw_tiles3d_provider *tiles3d;
    const struct tw_tileset *car_models;
    struct tw_traffic_settings traffic;
    uint32_t scenario_frames;           /* tw_run_scenarios: frames of each scenario (0: its own) */
    bool bench;                         /* summary.md, PNG names with the method, charts */
    bool split;                         /* --split: each frame's set drawn again (report.h) */
    bool defer_charts;                  /* a bench whose caller draws the charts (a sweep) */
    bool quiet;
    /* A progress line shared by several runs (a sweep's), borrowed: this
     * run's frames count from progress_base on it. NULL: the run has a line
     * of its own. */
    struct tw_progress *progress;
    uint32_t progress_base;
    bool allow_missed;                  /* --allow-missed: said in the verdict (report.h) */
    tw_run_frame_fn on_frame;
    void *on_frame_user;
    /* results */
    struct tw_method_figures figures[TW_METHOD_ALL];
    struct tw_report_about about;       /* what ran (of a sweep: its base run) */
    /* Under --verify, pixels that conservative methods missed, over every
     * run (a sweep's too). */
    uint64_t conservative_missed_pixels;
    int world_error;                    /* tw_world_create()'s error when it failed, else 0 */
};

/* Runs every frame of run->path with every method, writing frames.csv,
 * summary.json (and summary.md and charts for a bench) into run->out. The
 * context must be current and as large as run->world's size. On failure
 * returns a negative code with a one-line reason in err: TW_ERR_INVALID
 * when the output folder cannot be made, TW_ERR_IO when a file cannot be
 * written; when the world cannot be created, its error (also in
 * run->world_error: the library has logged why). */
int tw_run_execute(struct tw_run *run, struct tw_context *ctx, char *err, size_t err_size);

/* Makes a tileset again with another cluster size (for sweeps); returns a
 * new tileset the caller owns, or NULL with a reason in err. */
typedef struct tw_tileset *(*tw_tileset_maker_fn)(void *user, uint32_t cluster_triangles,
                                                  char *err, size_t err_size);

/* --sweep PARAM=v1,v2,...: the base run (written to run->out), then one run
 * per value into run->out/sweep-PARAM-VALUE/, and run->out/sweep.csv with
 * one row per method and value. PARAM is one of n_av, b, T,
 * cluster_triangles, evict_after, view_distance, neighbours,
 * max_screen_error, cars (run->car_models and traffic must be set). */
int tw_run_sweep(struct tw_run *run, struct tw_context *ctx, const char *spec,
                 tw_tileset_maker_fn make_tileset, void *maker_user, char *err, size_t err_size);

/* Checks a --sweep spec without running it (for the command line). */
int tw_run_sweep_check(const char *spec, char *err, size_t err_size);

/* Names of the stability scenarios, NULL-terminated. */
extern const char *const tw_scenario_names[];

/* --scenario NAME|all: runs each scenario over the run's tileset (not a
 * provider: scenarios place the camera by the prototypes) with every
 * conservative method under --verify, into run->out/scenario-NAME/, and
 * writes run->out/scenarios.md and scenarios.json saying what had to hold
 * and whether it held. *all_held tells whether every check held. */
int tw_run_scenarios(struct tw_run *run, struct tw_context *ctx, const char *name,
                     bool *all_held, char *err, size_t err_size);

#endif
