/*
 * Command lines of the tileworld programs (tileworld, tileworld-view), as
 * dav1d's tools/dav1d_cli_parse.c: a getopt_long table of the options the
 * programs share (TW_CLI_COMMON_OPTIONS), which each program extends with
 * its own, and one parser per kind of value. The options fill a
 * struct tw_world_settings, the library's own settings.
 *
 * Bad input is the user's: a parser ends the program with exit status
 * TW_CLI_EXIT_USAGE and exactly one line "PROGRAM: PLACE: reason" on
 * stderr (escaped by tw_cli_escape()), never a crash. getopt's own
 * messages are silenced. Linked into the executables only: it exits.
 *
 * Numbers mean what they say: only plain decimal digits (no sign where a
 * count is asked, no spaces, no 0x, no exponent, no inf or nan).
 */
#ifndef TW_TOOLS_CLI_H
#define TW_TOOLS_CLI_H

#include <getopt.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdnoreturn.h>

#include "runtime/runtime-internal.h"
#include "tiles/tiles-internal.h"
#include "tileworld/runtime.h"
#include "tileworld/tilesets.h"

#define TW_CLI_EXIT_USAGE 2

/* getopt_long values of the shared options; a program numbers its own from
 * TW_CLI_OPT_PROGRAM on. */
enum {
    TW_CLI_OPT_TILESET = 256,
    TW_CLI_OPT_SEED,
    TW_CLI_OPT_PATH,
    TW_CLI_OPT_FRAMES,
    TW_CLI_OPT_METHOD,
    TW_CLI_OPT_SIZE,
    TW_CLI_OPT_START_CELL,
    TW_CLI_OPT_REPEAT,
    TW_CLI_OPT_VIEW_DISTANCE,
    TW_CLI_OPT_QUIET,
    TW_CLI_OPT_WORKERS,
    TW_CLI_OPT_POLICY,
    TW_CLI_OPT_BUDGET,
    TW_CLI_OPT_UPLOAD_BUDGET,
    TW_CLI_OPT_MAX_SCREEN_ERROR,
    TW_CLI_OPT_HTTP_CACHE,
    TW_CLI_OPT_HTTP_CACHE_BYTES,
    TW_CLI_OPT_HTTP_TIMEOUT,
    TW_CLI_OPT_PROGRAM = 512,
};

/* The first entries of a program's struct option table. */
#define TW_CLI_COMMON_OPTIONS \
    {"tileset", required_argument, NULL, TW_CLI_OPT_TILESET}, \
    {"seed", required_argument, NULL, TW_CLI_OPT_SEED}, \
    {"path", required_argument, NULL, TW_CLI_OPT_PATH}, \
    {"frames", required_argument, NULL, TW_CLI_OPT_FRAMES}, \
    {"method", required_argument, NULL, TW_CLI_OPT_METHOD}, \
    {"size", required_argument, NULL, TW_CLI_OPT_SIZE}, \
    {"start-cell", required_argument, NULL, TW_CLI_OPT_START_CELL}, \
    {"repeat", required_argument, NULL, TW_CLI_OPT_REPEAT}, \
    {"view-distance", required_argument, NULL, TW_CLI_OPT_VIEW_DISTANCE}, \
    {"quiet", no_argument, NULL, TW_CLI_OPT_QUIET}, \
    {"workers", required_argument, NULL, TW_CLI_OPT_WORKERS}, \
    {"policy", required_argument, NULL, TW_CLI_OPT_POLICY}, \
    {"budget", required_argument, NULL, TW_CLI_OPT_BUDGET}, \
    {"upload-budget", required_argument, NULL, TW_CLI_OPT_UPLOAD_BUDGET}, \
    {"max-screen-error", required_argument, NULL, TW_CLI_OPT_MAX_SCREEN_ERROR}, \
    {"http-cache", required_argument, NULL, TW_CLI_OPT_HTTP_CACHE}, \
    {"http-cache-bytes", required_argument, NULL, TW_CLI_OPT_HTTP_CACHE_BYTES}, \
    {"http-timeout", required_argument, NULL, TW_CLI_OPT_HTTP_TIMEOUT}, \
    {"help", no_argument, NULL, 'h'}

/* The --help lines of the options of a baked tileset streamed back
 * (--tileset http://... or file://...), shared by the programs. */
#define TW_CLI_HTTP_HELP \
    "--http-cache DIR      a --tileset URL's tiles kept in DIR with their ETag, revalidated\n" \
    "                      (If-None-Match; a 304 serves the copy); default: no cache\n" \
    "--http-cache-bytes BYTES  the cache's files together; beyond it the oldest go\n" \
    "                      (default 1G)\n" \
    "--http-timeout MS     a request's whole time, 1..3600000 ms (default 30000); a\n" \
    "                      timeout, a 5xx or a lost connection is tried 3 more times\n" \
    "                      (back-off 0.1, 0.2, 0.4 s), then the tile is refused\n"

/* What the shared options set. */
struct tw_cli {
    const char *program;             /* "tileworld", for messages; borrowed */
    struct tw_world_settings world;  /* seed, repeat, method, size, view distance, workers,
                                      * policy, budgets, and what a program's own options add */
    struct tw_world_tuning tuning;   /* the methods' parameters and measurement switches */
    const char *tileset;             /* a built-in name, a manifest file or a URL of a baked
                                        tileset.json; borrowed from argv */
    struct tw_tiles3d_settings http; /* --http-cache, --http-cache-bytes, --http-timeout */
    const char *path;                /* a built-in path or a CSV file; NULL: none given */
    uint32_t frames;                 /* 0: the path's length */
    struct tw_cell start_cell;
    bool quiet;
    uint32_t given;                  /* shared options given: bit opt - TW_CLI_OPT_TILESET */
    _Atomic uint32_t errors_logged;  /* error lines tw_cli_log() printed (from any thread) */
};

/* Whether --tileset names a baked tileset by URL (http://, https://,
 * file://). */
bool tw_cli_is_url(const char *tileset);

/* True when the shared option opt (TW_CLI_OPT_*) was on the command line. */
bool tw_cli_given(const struct tw_cli *c, int opt);

/* Defaults: tileset city, seed 1, method tilequery+chc, view distance
 * 600 m; the program sets its own size and path. Calls
 * tw_cli_catch_crashes(program) first. */
void tw_cli_init(struct tw_cli *c, const char *program);
/* Where the programs keep the levels of detail (tw_world_settings.
 * levels_cache_dir): the environment's TW_LEVELS_CACHE ("" or "off":
 * nowhere), else $XDG_CACHE_HOME/tileworld/levels, else
 * $HOME/.cache/tileworld/levels; NULL: nowhere. */
const char *tw_cli_levels_cache(void);

/* Makes a crash (SIGSEGV, SIGBUS) end with one line on stderr before the
 * program dies of it: "PROGRAM: crashed (SIGSEGV) under an address-space
 * limit of N MiB (ulimit -v): most likely out of memory inside the OpenGL
 * driver or another library that does not check its allocations; raise the
 * limit" when RLIMIT_AS is finite (a software rasteriser that runs out of
 * address space crashes rather than fails), else "PROGRAM: crashed
 * (SIGSEGV): this is a bug, please report it". The program then dies of
 * the signal itself (exit status 128 + signal, 139 for SIGSEGV; a core dump
 * where they are enabled), not of an exit code of its own: a crash must not
 * read as an error the program handled, and a debugger or a core dump
 * still sees where it was. The line is made now (the handler only writes);
 * it runs on a stack of its own. Does nothing in a build with a sanitizer
 * (AddressSanitizer, ThreadSanitizer), and leaves a handler that was
 * installed already in place. */
void tw_cli_catch_crashes(const char *program);

/* Applies one of a program's own options: opt is its getopt_long value,
 * name its long name (for messages, "--name"), arg its value or NULL. */
typedef void (*tw_cli_apply_fn)(void *user, int opt, const char *name, const char *arg);

/* Parses argv[1..argc-1] with getopt_long over options (which starts with
 * TW_CLI_COMMON_OPTIONS and ends with a zeroed entry): --opt=value and
 * --opt value alike. Shared options go into c, the others to apply;
 * --help / -h prints usage to stdout and exits 0. An unknown or ambiguous
 * option, a missing value or an argument that is not an option fails. */
void tw_cli_parse(struct tw_cli *c, int argc, char **argv, const struct option *options,
                  tw_cli_apply_fn apply, void *user, void (*usage)(FILE *f));

/* Prints "program: " and the formatted text on stderr as one line, with
 * control characters escaped. */
void tw_cli_message(const char *program, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* Prints "program: place: " and the formatted reason as one line (escaped),
 * then exits with TW_CLI_EXIT_USAGE. */
noreturn void tw_cli_fail(const char *program, const char *place, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* Writes s into out (out_size bytes) as one line of plain text that
 * cannot drive a terminal: tiles.h's tw_log_escape_reversible() (newline,
 * carriage return and tab as \n, \r, \t; other control characters, DEL and
 * bytes that are not valid UTF-8 as \xHH; the C1 controls and the
 * bidirectional overrides as \uHHHH; a backslash as \\; "..." ends a cut).
 * At most four bytes out per byte in. Returns out. */
char *tw_cli_escape(const char *s, char *out, size_t out_size);

/* The forms of a plain decimal number. */
enum tw_cli_number {
    TW_CLI_COUNT,     /* digits only: 0, 42 */
    TW_CLI_INTEGER,   /* digits with an optional leading '-' */
    TW_CLI_DECIMAL,   /* an integer with an optional fraction: -1.5, 600, 0.25 */
};

/* True when s is a plain decimal number of that form, and nothing else. */
bool tw_cli_is_number(const char *s, enum tw_cli_number form);

/* A whole number in [lo, hi]. */
uint64_t tw_cli_u64(const char *program, const char *opt, const char *s, uint64_t lo, uint64_t hi);
/* A signed 64-bit whole number. */
int64_t tw_cli_i64(const char *program, const char *opt, const char *s);
/* A decimal number in [lo, hi]. */
float tw_cli_float(const char *program, const char *opt, const char *s, float lo, float hi);
/* WIDTHxHEIGHT, each in [16, 8192]. */
void tw_cli_size(const char *program, const char *opt, const char *s, uint32_t *w, uint32_t *h);
/* I,J within +-2^62 cells, where neighbour arithmetic cannot overflow. */
void tw_cli_cell(const char *program, const char *opt, const char *s, struct tw_cell *c);
/* A byte count: digits with an optional binary suffix K, M, G or T (also
 * KiB, MiB, GiB, TiB; 64M = 64 MiB), at most hi bytes. */
uint64_t tw_cli_bytes(const char *program, const char *opt, const char *s, uint64_t hi);
/* A stream policy: "wait" or "skip". */
enum tw_stream_policy tw_cli_policy(const char *program, const char *opt, const char *s);
/* A method implemented in this build. */
enum tw_method tw_cli_method(const char *program, const char *opt, const char *s);

/* A logger that prints warnings and errors as tw_cli_message() lines and
 * counts the errors in errors_logged; user is the struct tw_cli (not
 * const: the count is written, atomically, from any thread). */
void tw_cli_log(void *user, enum tw_log_level level, const char *msg);

/* The tileset of --tileset (a built-in one, made with clusters of at most
 * cluster_triangles, 0: the default; or a manifest): the caller owns it.
 * Exits on failure (status 2 for bad input, 1 otherwise). */
struct tw_tileset *tw_cli_load_tileset(const struct tw_cli *c, uint32_t cluster_triangles,
                                       const struct tw_log *log);

/* What a world shows, from --tileset: a fixed tileset (built-in or a
 * manifest), a built-in provider (city-gen, forest-gen) or a baked tileset
 * streamed back (http://, https://, file://). Exactly one of tileset,
 * provider and tiles3d is set; all are owned by this struct. */
struct tw_cli_world {
    struct tw_tileset *tileset;             /* a fixed tileset, or NULL */
    struct tw_tilesets_provider *provider;  /* a built-in provider, or NULL */
    struct tw_tiles3d_provider *tiles3d;    /* a baked tileset streamed back, or NULL */
    const struct tw_tile_provider *source;  /* the provider's (borrowed from provider), or NULL */
    const char *name;                       /* the tileset's or the provider's name; borrowed */
    float footprint[2];                     /* W, D metres of the grid's cells */
};

/* Loads what --tileset names (a provider's tiles and a built-in tileset
 * made with clusters of at most cluster_triangles, 0: the default). Exits on
 * failure (status 2 for bad input, 1 otherwise). */
void tw_cli_world_load(const struct tw_cli *c, uint32_t cluster_triangles,
                       const struct tw_log *log, struct tw_cli_world *out);
/* Sets ws->tileset or ws->provider (the other NULL) to what w shows. */
void tw_cli_world_apply(const struct tw_cli_world *w, struct tw_world_settings *ws);
/* Frees what w owns; accepts a zeroed w. Where a destroyed world left
 * workers behind (tw_cli_world_destroy), the providers stay: those
 * workers may still be in their code. */
void tw_cli_world_finish(struct tw_cli_world *w);
/* tw_world_destroy(), counting the workers it left behind (stuck in a
 * provider's generate() past the shutdown timeout). */
void tw_cli_world_destroy(struct tw_world *w);
/* How a program ends with status rc: where workers were left behind, at
 * once (stdio flushed, no exit-time destructors: Embree's, libcurl's and
 * the C library's would run under those threads), after a line that says
 * so; else it returns rc. */
int tw_cli_exit(const char *program, int rc);
/* For a baked tileset streamed back (w->tiles3d), the line that ends a
 * run on stderr: the tiles read and what the fetches did. Nothing for
 * another world. */
void tw_cli_world_tiles3d_line(const char *program, const struct tw_cli_world *w);

/* How a failed tw_world_create() ends a program: for bad input
 * (TW_ERR_INVALID, TW_ERR_LIMIT) TW_CLI_EXIT_USAGE, else 1. */
int tw_cli_world_exit_status(int err);

/* The camera path name (a built-in one of frames keys, or a CSV file of
 * c->frames rows, 0: all) over cells of footprint (W, D metres), moved by
 * --start-cell, into *p (the caller finishes it). Exits on failure. */
void tw_cli_load_path(const struct tw_cli *c, const char *name, uint32_t frames,
                      const float footprint[2], struct tw_path *p);

#endif
