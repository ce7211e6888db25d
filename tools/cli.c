/* Command lines of the tileworld programs (cli.h). */
/* sigaltstack() and SA_ONSTACK are XSI: the crash handler runs on a stack of
 * its own, so that it can still say something when the stack is what ran
 * out. */
#define _XOPEN_SOURCE 700

#include "tiles/tiles-internal.h"
#include "tilesets/tilesets-private.h"
#include "tools/cli.h"

#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>

char *tw_cli_escape(const char *s, char *out, size_t out_size)
{
    tw_log_escape_reversible(s, out, out_size);
    return out;
}

/* ---- crashes ------------------------------------------------------------------------ */

/* What the handler writes, made when it is installed: it may only call
 * async-signal-safe functions (write, signal, raise). */
static char crash_head[96];        /* "PROGRAM: crashed (" */
static char crash_tail[320];       /* "): ... \n" */
static size_t crash_head_len, crash_tail_len;
static char crash_stack[64 * 1024];

static void crash_write(const char *text, size_t len)
{
    while (len > 0) {
        const ssize_t n = write(STDERR_FILENO, text, len);
        if (n <= 0)
            return;
        text += n;
        len -= (size_t)n;
    }
}

static void crashed(int sig)
{
    crash_write(crash_head, crash_head_len);
    if (sig == SIGBUS)
        crash_write("SIGBUS", 6);
    else
        crash_write("SIGSEGV", 7);
    crash_write(crash_tail, crash_tail_len);
    /* Die of the signal itself (status 128 + sig, a core dump where they are
     * on): delivered as soon as this handler returns. */
    signal(sig, SIG_DFL);
    raise(sig);
}

/* True when this build runs under a sanitizer that handles crashes itself. */
static bool sanitized(void)
{
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
    return true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || \
    __has_feature(memory_sanitizer)
    return true;
#else
    return false;
#endif
#else
    return false;
#endif
}

void tw_cli_catch_crashes(const char *program)
{
    if (sanitized())
        return;
    struct rlimit rl;
    const bool limited = getrlimit(RLIMIT_AS, &rl) == 0 && rl.rlim_cur != RLIM_INFINITY;
    snprintf(crash_head, sizeof(crash_head), "%s: crashed (", program);
    if (limited)
        snprintf(crash_tail, sizeof(crash_tail),
                 ") under an address-space limit of %llu MiB (ulimit -v): most likely out of "
                 "memory inside the OpenGL driver or another library that does not check its "
                 "allocations; raise the limit\n", (unsigned long long)(rl.rlim_cur >> 20));
    else
        snprintf(crash_tail, sizeof(crash_tail), "): this is a bug, please report it\n");
    crash_head_len = strlen(crash_head);
    crash_tail_len = strlen(crash_tail);
    const stack_t stack = {.ss_sp = crash_stack, .ss_size = sizeof(crash_stack)};
    const bool own_stack = sigaltstack(&stack, NULL) == 0;
    const int signals[2] = {SIGSEGV, SIGBUS};
    for (int k = 0; k < 2; k++) {
        /* A handler installed already (a sanitizer's, a debugging tool's)
         * stays: it knows more than this one. */
        struct sigaction old;
        if (sigaction(signals[k], NULL, &old) != 0 ||
            ((old.sa_flags & SA_SIGINFO) ? old.sa_sigaction != NULL
                                         : old.sa_handler != SIG_DFL))
            continue;
        struct sigaction sa;
        memset(&sa, 0, sizeof(sa));
        sa.sa_handler = crashed;
        sigemptyset(&sa.sa_mask);
        sa.sa_flags = own_stack ? SA_ONSTACK : 0;
        sigaction(signals[k], &sa, NULL);
    }
}

static void vmessage(const char *program, const char *place, const char *fmt, va_list ap)
{
    char text[2048], escaped[4 * sizeof(text)];
    vsnprintf(text, sizeof(text), fmt, ap);
    if (place) {
        char where[4 * 256];
        fprintf(stderr, "%s: %s: %s\n", program, tw_cli_escape(place, where, sizeof(where)),
                tw_cli_escape(text, escaped, sizeof(escaped)));
    } else {
        fprintf(stderr, "%s: %s\n", program, tw_cli_escape(text, escaped, sizeof(escaped)));
    }
}

void tw_cli_message(const char *program, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vmessage(program, NULL, fmt, ap);
    va_end(ap);
}

noreturn void tw_cli_fail(const char *program, const char *place, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vmessage(program, place, fmt, ap);
    va_end(ap);
    exit(TW_CLI_EXIT_USAGE);
}

static bool is_digit(char c)
{
    return c >= '0' && c <= '9';
}

bool tw_cli_is_number(const char *s, enum tw_cli_number form)
{
    if (!s)
        return false;
    if (form != TW_CLI_COUNT && *s == '-')
        s++;
    size_t digits = 0;
    while (is_digit(*s)) {
        s++;
        digits++;
    }
    if (form == TW_CLI_DECIMAL && *s == '.' && digits > 0) {
        s++;
        size_t fraction = 0;
        while (is_digit(*s)) {
            s++;
            fraction++;
        }
        if (fraction == 0)
            return false;
    }
    return digits > 0 && *s == '\0';
}

uint64_t tw_cli_u64(const char *program, const char *opt, const char *s, uint64_t lo, uint64_t hi)
{
    if (!tw_cli_is_number(s, TW_CLI_COUNT))
        tw_cli_fail(program, opt, "'%s' is not a whole number of decimal digits in [%llu, %llu]",
                    s ? s : "", (unsigned long long)lo, (unsigned long long)hi);
    errno = 0;
    const unsigned long long v = strtoull(s, NULL, 10);
    if (errno == ERANGE || v < lo || v > hi)
        tw_cli_fail(program, opt, "'%s' is out of range [%llu, %llu]", s, (unsigned long long)lo,
                    (unsigned long long)hi);
    return v;
}

int64_t tw_cli_i64(const char *program, const char *opt, const char *s)
{
    if (!tw_cli_is_number(s, TW_CLI_INTEGER))
        tw_cli_fail(program, opt, "'%s' is not a whole number of decimal digits (with '-' when "
                    "negative)", s ? s : "");
    errno = 0;
    const long long v = strtoll(s, NULL, 10);
    if (errno == ERANGE)
        tw_cli_fail(program, opt, "'%s' does not fit in 64 bits", s);
    return v;
}

float tw_cli_float(const char *program, const char *opt, const char *s, float lo, float hi)
{
    if (!tw_cli_is_number(s, TW_CLI_DECIMAL))
        tw_cli_fail(program, opt, "'%s' is not a decimal number such as 600 or 12.5 (in [%g, %g])",
                    s ? s : "", lo, hi);
    errno = 0;
    const double v = strtod(s, NULL);
    if (errno == ERANGE || !isfinite(v) || v < lo || v > hi)
        tw_cli_fail(program, opt, "'%s' is out of range [%g, %g]", s, lo, hi);
    return (float)v;
}

/* Splits "A<sep>B" into first (copied, at most 31 characters) and *second. */
static void split_pair(const char *program, const char *opt, const char *s, char sep,
                       const char *form, char first[32], const char **second)
{
    const char *at = s ? strchr(s, sep) : NULL;
    const size_t n = at ? (size_t)(at - s) : 0;
    if (!at || n == 0 || n >= 32)
        tw_cli_fail(program, opt, "'%s' is not of the form %s", s ? s : "", form);
    memcpy(first, s, n);
    first[n] = '\0';
    *second = at + 1;
}

void tw_cli_size(const char *program, const char *opt, const char *s, uint32_t *w, uint32_t *h)
{
    char first[32];
    const char *second;
    split_pair(program, opt, s, 'x', "WIDTHxHEIGHT", first, &second);
    *w = (uint32_t)tw_cli_u64(program, opt, first, 16, 8192);
    *h = (uint32_t)tw_cli_u64(program, opt, second, 16, 8192);
}

void tw_cli_cell(const char *program, const char *opt, const char *s, struct tw_cell *c)
{
    char first[32];
    const char *second;
    split_pair(program, opt, s, ',', "I,J", first, &second);
    c->i = tw_cli_i64(program, opt, first);
    c->j = tw_cli_i64(program, opt, second);
    /* Keep cells where neighbour arithmetic cannot overflow. */
    const int64_t limit = (int64_t)1 << 62;
    if (c->i > limit || c->i < -limit || c->j > limit || c->j < -limit)
        tw_cli_fail(program, opt, "'%s' lies outside +-2^62 cells", s);
}

/* names (NULL-terminated) as "a, b, c" in out. */
static const char *join(const char *const *names, char *out, size_t size)
{
    size_t n = 0;
    out[0] = '\0';
    for (const char *const *k = names; *k && n < size; k++)
        n += (size_t)snprintf(out + n, size - n, "%s%s", k > names ? ", " : "", *k);
    return out;
}

enum tw_method tw_cli_method(const char *program, const char *opt, const char *s)
{
    enum tw_method m;
    if (tw_method_or_limit_from_name(s, &m) != TW_OK) {
        const char *list[TW_METHOD_ALL + 1] = {NULL};
        for (int k = TW_METHOD_FIRST; k < TW_METHOD_ALL; k++)
            list[k - TW_METHOD_FIRST] = tw_method_name((enum tw_method)k);
        char names[256];
        tw_cli_fail(program, opt, "unknown method '%s' (%s)", s, join(list, names, sizeof(names)));
    }
    return m;
}

uint64_t tw_cli_bytes(const char *program, const char *opt, const char *s, uint64_t hi)
{
    static const char units[] = "KMGT";
    size_t digits = 0;
    while (s && is_digit(s[digits]))
        digits++;
    const char *suffix = s ? s + digits : "";
    unsigned shift = 0;
    if (*suffix) {
        const char *u = strchr(units, suffix[0]);
        if (u && (suffix[1] == '\0' || strcmp(suffix + 1, "iB") == 0))
            shift = 10u * (unsigned)(u - units + 1);
        else
            digits = 0;
    }
    if (digits == 0 || digits > 20)
        tw_cli_fail(program, opt, "'%s' is not a byte count such as 1048576, 512K, 64M or 1G "
                    "(binary: 64M = 64 MiB)", s ? s : "");
    char number[32];
    memcpy(number, s, digits);
    number[digits] = '\0';
    errno = 0;
    const unsigned long long v = strtoull(number, NULL, 10);
    if (errno == ERANGE || (shift && v > (UINT64_MAX >> shift)) || (v << shift) > hi)
        tw_cli_fail(program, opt, "'%s' is more than %llu bytes", s, (unsigned long long)hi);
    return (uint64_t)v << shift;
}

enum tw_stream_policy tw_cli_policy(const char *program, const char *opt, const char *s)
{
    if (s && strcmp(s, "wait") == 0)
        return TW_STREAM_WAIT;
    if (s && strcmp(s, "skip") == 0)
        return TW_STREAM_SKIP;
    tw_cli_fail(program, opt, "unknown policy '%s' (wait: a frame waits for its tiles; skip: it "
                "draws without the ones not ready)", s ? s : "");
}

void tw_cli_log(void *user, enum tw_log_level level, const char *msg)
{
    struct tw_cli *c = user;
    if (level <= TW_LOG_WARN)
        tw_cli_message(c->program, "%s", msg);
    if (level <= TW_LOG_ERROR)
        c->errors_logged++;
}

struct tw_tileset *tw_cli_load_tileset(const struct tw_cli *c, uint32_t cluster_triangles,
                                       const struct tw_log *log)
{
    struct tw_tileset *ts = NULL;
    for (const char *const *n = tw_tilesets_builtin_names; *n; n++) {
        if (strcmp(*n, c->tileset) != 0)
            continue;
        const int err = tw_tilesets_builtin(c->tileset, c->world.selection.seed, cluster_triangles,
                                            log, &ts);
        if (err) {
            tw_cli_message(c->program, "--tileset %s: generation failed: %s", c->tileset,
                           tw_error_to_str(err));
            exit(1);
        }
        return ts;
    }
    /* A name that looks like a file (a '/' or ".json" at its end) goes to
     * the loader, which says "<path>: no such file" when it is missing. */
    const size_t len = strlen(c->tileset);
    const bool file_like = strchr(c->tileset, '/') ||
                           (len > 5 && strcmp(c->tileset + len - 5, ".json") == 0);
    if (!file_like && access(c->tileset, F_OK) != 0)
        tw_cli_fail(c->program, "--tileset", "unknown tileset '%s' (built-in: city, forest, hybrid; "
                    "providers: city-gen, forest-gen; or a manifest file)", c->tileset);
    /* A manifest: its loader logs one line naming the file, the place and the reason. */
    const struct tw_manifest_settings ms = {.max_cluster_triangles = cluster_triangles};
    const int err = tw_tilesets_load_manifest(c->tileset, &ms, log, &ts);
    if (err)
        exit(err == TW_ERR_NOMEM ? 1 : TW_CLI_EXIT_USAGE);
    return ts;
}

bool tw_cli_is_url(const char *tileset)
{
    return tileset && (strncmp(tileset, "http://", 7) == 0 ||
                       strncmp(tileset, "https://", 8) == 0 || strncmp(tileset, "file://", 7) == 0);
}

void tw_cli_world_load(const struct tw_cli *c, uint32_t cluster_triangles,
                       const struct tw_log *log, struct tw_cli_world *out)
{
    memset(out, 0, sizeof(*out));
    if (tw_cli_is_url(c->tileset)) {
        struct tw_tiles3d_settings s = c->http;
        s.max_cluster_triangles = cluster_triangles;
        const int err = tw_tiles3d_provider_create(c->tileset, &s, log, &out->tiles3d);
        if (err) {
            /* The library said why in its own line. */
            exit(err == TW_ERR_INVALID || err == TW_ERR_FORMAT ? TW_CLI_EXIT_USAGE : 1);
        }
        out->source = tw_tiles3d_provider_get(out->tiles3d);
        out->name = c->tileset;
        out->footprint[0] = out->source->footprint[0];
        out->footprint[1] = out->source->footprint[1];
        return;
    }
    if (!tw_tilesets_is_provider(c->tileset)) {
        out->tileset = tw_cli_load_tileset(c, cluster_triangles, log);
        out->name = out->tileset->name;
        out->footprint[0] = out->tileset->footprint[0];
        out->footprint[1] = out->tileset->footprint[1];
        return;
    }
    const int err = tw_tilesets_provider_create(c->tileset, c->world.selection.seed,
                                                cluster_triangles, log, &out->provider);
    if (err) {
        tw_cli_message(c->program, "--tileset %s: the provider cannot start: %s", c->tileset,
                       tw_error_to_str(err));
        exit(err == TW_ERR_INVALID ? TW_CLI_EXIT_USAGE : 1);
    }
    out->source = tw_tilesets_provider_get(out->provider);
    out->name = out->source->name ? out->source->name : c->tileset;
    out->footprint[0] = out->source->footprint[0];
    out->footprint[1] = out->source->footprint[1];
}

void tw_cli_world_apply(const struct tw_cli_world *w, struct tw_world_settings *ws)
{
    ws->tileset = w->tileset;
    ws->provider = w->source;
}

/* Workers the program's worlds left behind, still running. */
static uint32_t left_behind;

void tw_cli_world_destroy(struct tw_world *w)
{
    left_behind += tw_world_destroy(w);
}

void tw_cli_world_finish(struct tw_cli_world *w)
{
    tw_tileset_destroy(w->tileset);
    if (left_behind == 0) {
        tw_tilesets_provider_destroy(w->provider);
        tw_tiles3d_provider_destroy(w->tiles3d);
    }
    memset(w, 0, sizeof(*w));
}

int tw_cli_exit(const char *program, int rc)
{
    if (left_behind == 0)
        return rc;
    tw_cli_message(program, "%u tile worker%s still in the provider's generate(): ending without "
                   "waiting for %s", left_behind, left_behind == 1 ? "" : "s",
                   left_behind == 1 ? "it" : "them");
    fflush(NULL);
    _exit(rc);
}

void tw_cli_world_tiles3d_line(const char *program, const struct tw_cli_world *w)
{
    if (!w->tiles3d)
        return;
    struct tw_tiles3d_stats hs;
    tw_tiles3d_provider_stats(w->tiles3d, &hs);
    tw_cli_message(program, "3D Tiles: %llu cells and %llu blocks of coarser levels read; "
                   "%llu requests, %llu bytes, %llu cache hits, %llu not modified (304), %llu "
                   "retries, %llu failures, %llu stale copies",
                   (unsigned long long)hs.cells, (unsigned long long)hs.blocks,
                   (unsigned long long)hs.requests, (unsigned long long)hs.bytes,
                   (unsigned long long)hs.cache_hits, (unsigned long long)hs.not_modified,
                   (unsigned long long)hs.retries, (unsigned long long)hs.failures,
                   (unsigned long long)hs.stale);
}

int tw_cli_world_exit_status(int err)
{
    return err == TW_ERR_INVALID || err == TW_ERR_LIMIT ? TW_CLI_EXIT_USAGE : 1;
}

void tw_cli_load_path(const struct tw_cli *c, const char *name, uint32_t frames,
                      const float footprint[2], struct tw_path *p)
{
    const float w = footprint[0], d = footprint[1];
    bool builtin = false;
    for (const char *const *n = tw_path_builtin_names; *n; n++)
        builtin |= strcmp(*n, name) == 0;
    if (builtin) {
        const int err = tw_path_builtin(name, c->world.selection.seed, frames, 0.0f, w, d, p);
        if (err) {
            tw_cli_message(c->program, "--path %s: %s", name, tw_error_to_str(err));
            exit(1);
        }
    } else {
        char msg[1400];
        const int err = tw_path_load_csv(name, c->frames, w, d, p, msg, sizeof(msg));
        if (err) {
            if (err == TW_ERR_IO && access(name, F_OK) != 0 && !strchr(name, '/') &&
                !strstr(name, ".csv")) {
                char names[256];
                tw_cli_fail(c->program, "--path", "unknown path '%s' (built-in: %s; or a CSV file)",
                            name, join(tw_path_builtin_names, names, sizeof(names)));
            }
            tw_cli_message(c->program, "%s", msg);
            exit(TW_CLI_EXIT_USAGE);
        }
    }
    if (tw_path_translate(p, c->start_cell.i, c->start_cell.j))
        tw_cli_fail(c->program, "--start-cell", "the translated path overflows the grid");
}

void tw_cli_init(struct tw_cli *c, const char *program)
{
    tw_cli_catch_crashes(program);
    memset(c, 0, sizeof(*c));
    c->program = program;
    c->tileset = "city";
    c->world.selection.seed = 1;
    c->world.method = TW_METHOD_TILEQUERY_CHC;
    c->world.view_distance = 600.0f;
    c->world.max_screen_error = 1.0f;
    c->world.levels_cache_dir = tw_cli_levels_cache();
}

const char *tw_cli_levels_cache(void)
{
    static char dir[4096];
    const char *env = getenv("TW_LEVELS_CACHE");
    if (env)
        return env[0] && strcmp(env, "off") != 0 ? env : NULL;
    const char *xdg = getenv("XDG_CACHE_HOME"), *home = getenv("HOME");
    int n = -1;
    if (xdg && xdg[0] == '/')
        n = snprintf(dir, sizeof(dir), "%s/tileworld/levels", xdg);
    else if (home && home[0] == '/')
        n = snprintf(dir, sizeof(dir), "%s/.cache/tileworld/levels", home);
    return n > 0 && (size_t)n < sizeof(dir) ? dir : NULL;
}

/* Applies a shared option; false for a program's own. */
static bool apply_common(struct tw_cli *c, int opt, const char *place, const char *arg)
{
    const char *p = c->program;
    struct tw_world_settings *ws = &c->world;
    switch (opt) {
    case TW_CLI_OPT_TILESET: c->tileset = arg; break;
    case TW_CLI_OPT_SEED: ws->selection.seed = tw_cli_u64(p, place, arg, 0, UINT64_MAX); break;
    case TW_CLI_OPT_PATH: c->path = arg; break;
    case TW_CLI_OPT_FRAMES: c->frames = (uint32_t)tw_cli_u64(p, place, arg, 1, TW_PATH_MAX_ROWS); break;
    case TW_CLI_OPT_METHOD: ws->method = tw_cli_method(p, place, arg); break;
    case TW_CLI_OPT_SIZE: tw_cli_size(p, place, arg, &ws->width, &ws->height); break;
    case TW_CLI_OPT_START_CELL: tw_cli_cell(p, place, arg, &c->start_cell); break;
    case TW_CLI_OPT_REPEAT:
        ws->selection.repeat = (int64_t)tw_cli_u64(p, place, arg, 1, (uint64_t)1 << 62);
        break;
    case TW_CLI_OPT_VIEW_DISTANCE:
        ws->view_distance = tw_cli_float(p, place, arg, 1.0f, 100000.0f);
        break;
    case TW_CLI_OPT_MAX_SCREEN_ERROR:
        /* 0 on the command line is full detail; the library reads 0 as its default. */
        ws->max_screen_error = tw_cli_float(p, place, arg, 0.0f, 1000.0f);
        if (ws->max_screen_error == 0.0f)
            ws->max_screen_error = TW_FULL_DETAIL;
        break;
    case TW_CLI_OPT_QUIET: c->quiet = true; break;
    case TW_CLI_OPT_WORKERS: ws->workers = (uint32_t)tw_cli_u64(p, place, arg, 1, 64); break;
    case TW_CLI_OPT_POLICY: ws->policy = tw_cli_policy(p, place, arg); break;
    case TW_CLI_OPT_BUDGET:
        ws->cache_budget_bytes = tw_cli_bytes(p, place, arg, (uint64_t)1 << 50);
        break;
    case TW_CLI_OPT_UPLOAD_BUDGET:
        /* The library reads 0 as its default (32 MiB): at least one byte here. */
        ws->upload_budget_bytes = tw_cli_bytes(p, place, arg, (uint64_t)1 << 50);
        if (ws->upload_budget_bytes == 0)
            tw_cli_fail(p, place, "'%s' is not above 0 bytes", arg);
        break;
    case TW_CLI_OPT_HTTP_CACHE:
        if (!arg[0])
            tw_cli_fail(p, place, "needs a folder");
        c->http.cache_dir = arg;
        break;
    case TW_CLI_OPT_HTTP_CACHE_BYTES:
        c->http.cache_max_bytes = tw_cli_bytes(p, place, arg, (uint64_t)1 << 50);
        if (c->http.cache_max_bytes == 0)
            tw_cli_fail(p, place, "'%s' is not above 0 bytes", arg);
        break;
    case TW_CLI_OPT_HTTP_TIMEOUT:
        c->http.timeout_ms = (uint32_t)tw_cli_u64(p, place, arg, 1, 3600000);
        break;
    default: return false;
    }
    c->given |= 1u << (opt - TW_CLI_OPT_TILESET);
    return true;
}

bool tw_cli_given(const struct tw_cli *c, int opt)
{
    return opt >= TW_CLI_OPT_TILESET && opt < TW_CLI_OPT_TILESET + 32 &&
           (c->given >> (opt - TW_CLI_OPT_TILESET) & 1u);
}

static const struct option *find_option(const struct option *options, int val)
{
    for (const struct option *o = options; o->name; o++)
        if (o->val == val)
            return o;
    return NULL;
}

/* "--name" of an argument such as "--name=value". */
static void option_word(const char *arg, char *out, size_t size)
{
    const char *eq = strchr(arg, '=');
    const size_t n = eq ? (size_t)(eq - arg) : strlen(arg);
    snprintf(out, size, "%.*s", (int)n, arg);
}

/* How many long options start with the name of "--name[=value]". */
static int prefix_matches(const struct option *options, const char *word)
{
    if (strncmp(word, "--", 2) != 0)
        return 0;
    const size_t n = strlen(word + 2);
    int count = 0;
    for (const struct option *o = options; o->name; o++)
        count += strncmp(o->name, word + 2, n) == 0;
    return count;
}

void tw_cli_parse(struct tw_cli *c, int argc, char **argv, const struct option *options,
                  tw_cli_apply_fn apply, void *user, void (*usage)(FILE *f))
{
    const char *p = c->program;
    opterr = 0;
    optind = 1;
    for (;;) {
        int index = -1;
        const int opt = getopt_long(argc, argv, ":h", options, &index);
        if (opt == -1)
            break;
        char word[128];
        if (opt == '?') {
            option_word(argv[optind - 1], word, sizeof(word));
            const struct option *flag = optopt ? find_option(options, optopt) : NULL;
            if (flag && flag->has_arg == no_argument)
                tw_cli_fail(p, word, "takes no value");
            if (prefix_matches(options, word) > 1)
                tw_cli_fail(p, word, "ambiguous option '%s' (see %s --help)", word, p);
            tw_cli_fail(p, word, "unknown option '%s' (see %s --help)", word, p);
        }
        const struct option *o = opt == ':' ? find_option(options, optopt)
                                 : index >= 0 ? &options[index] : find_option(options, opt);
        if (o)
            snprintf(word, sizeof(word), "--%s", o->name);
        else
            option_word(argv[optind - 1], word, sizeof(word));
        if (opt == ':')
            tw_cli_fail(p, word, "needs a value");
        if (opt == 'h') {
            usage(stdout);
            exit(0);
        }
        if (!apply_common(c, opt, word, optarg))
            apply(user, opt, word, optarg);
    }
    if (optind < argc)
        tw_cli_fail(p, argv[optind], "unexpected argument '%s' (options start with --)",
                    argv[optind]);
}
