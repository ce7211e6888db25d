/* The progress line of the tileworld programs (progress.h). */
#include "tools/progress.h"

#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <time.h>
#include <unistd.h>

#include "tools/cli.h"

/* A terminal's line is redrawn at most this often: a frame a millisecond
 * would otherwise spend its time writing to the terminal. */
#define TTY_REFRESH_S 0.25
#define MAX_INTERVAL_S 86400.0

double tw_progress_now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

char *tw_progress_hms(double seconds, char *out, size_t out_size)
{
    if (!(seconds >= 0.0) || !isfinite(seconds)) {
        snprintf(out, out_size, "-:--:--");
        return out;
    }
    /* A year and more is shown as hours all the same, but bounded. */
    const uint64_t s = (uint64_t)(fmin(seconds, 1e12) + 0.5);
    snprintf(out, out_size, "%llu:%02u:%02u", (unsigned long long)(s / 3600),
             (unsigned)(s / 60 % 60), (unsigned)(s % 60));
    return out;
}

static unsigned terminal_columns(void)
{
#if defined(TIOCGWINSZ)
    struct winsize w;
    if (ioctl(STDERR_FILENO, TIOCGWINSZ, &w) == 0 && w.ws_col >= 20)
        return w.ws_col;
#endif
    return 80;
}

void tw_progress_init(struct tw_progress *p, const char *label, double total, const char *unit,
                      int decimals, bool quiet)
{
    memset(p, 0, sizeof(*p));
    p->out = stderr;
    tw_cli_escape(label ? label : "", p->label, sizeof(p->label));
    p->unit = unit;
    p->total = total > 0.0 ? total : 1.0;
    p->decimals = decimals < 0 ? 0 : decimals > 6 ? 6 : decimals;
    p->quiet = quiet;
    p->tty = !quiet && isatty(STDERR_FILENO);
    p->columns = p->tty ? terminal_columns() : 80;
    p->interval_s = TW_PROGRESS_INTERVAL_DEFAULT_S;
    const char *v = getenv(TW_PROGRESS_INTERVAL_ENV);
    if (v && *v) {
        const double s = tw_cli_is_number(v, TW_CLI_DECIMAL) ? strtod(v, NULL) : -1.0;
        if (s >= 0.0 && s <= MAX_INTERVAL_S)
            p->interval_s = s;
        else if (!quiet)
            tw_cli_message("tileworld", "warning: %s='%s' is not a number of seconds from 0 to "
                           "%.0f: a progress line every %.0f s", TW_PROGRESS_INTERVAL_ENV, v,
                           MAX_INTERVAL_S, TW_PROGRESS_INTERVAL_DEFAULT_S);
    }
    p->start_s = tw_progress_now_s();
    p->last_print_s = p->start_s;
}

/* Units a second from the first update to the last, or 0 while that cannot
 * be told. */
static double rate(const struct tw_progress *p)
{
    const double dt = p->done_s - p->first_s, dd = p->done - p->first_done;
    return p->started && dt > 0.0 && dd > 0.0 ? dd / dt : 0.0;
}

static void format_rate(double r, char *out, size_t out_size)
{
    if (r >= 999.5)
        snprintf(out, out_size, "%.0f", r);
    else
        snprintf(out, out_size, "%.3g", r);
}

/* "LABEL: 120/300 frames (40.0 %)" into line; returns its length. */
static size_t format_done(const struct tw_progress *p, const char *before, char *line, size_t size)
{
    const int n = snprintf(line, size, "%s: %s%.*f/%.*f %s (%.1f %%)", p->label, before,
                           p->decimals, p->done, p->decimals, p->total, p->unit,
                           100.0 * p->done / p->total);
    return n < 0 ? 0 : (size_t)n < size ? (size_t)n : size - 1;
}

/* Appends printf text to line (size bytes, len used); returns the new length. */
#if defined(__GNUC__)
__attribute__((format(printf, 4, 5)))
#endif
static size_t append(char *line, size_t size, size_t len, const char *fmt, ...)
{
    if (len + 1 >= size)
        return len;
    va_list ap;
    va_start(ap, fmt);
    const int n = vsnprintf(line + len, size - len, fmt, ap);
    va_end(ap);
    if (n < 0)
        return len;
    return len + (size_t)n < size ? len + (size_t)n : size - 1;
}

/* Puts line on the terminal in place of what is there, cut to its width. */
static void show(struct tw_progress *p, char *line, size_t len)
{
    if (p->columns > 1 && len > p->columns - 1) {
        len = p->columns - 1;
        line[len] = '\0';
    }
    const int pad = p->shown > len ? (int)(p->shown - len) : 0;
    fprintf(p->out, "\r%s%*s", line, pad, "");
    p->shown = len;
}

void tw_progress_update_at(struct tw_progress *p, double done, const char *note, double now_s)
{
    if (p->quiet)
        return;
    p->done = done < 0.0 ? 0.0 : done > p->total ? p->total : done;
    p->done_s = now_s;
    if (!p->started) {
        p->started = true;
        p->first_s = now_s;
        p->first_done = p->done;
    }
    const double since = now_s - p->last_print_s;
    if (p->tty ? p->printed && since < TTY_REFRESH_S : since < p->interval_s)
        return;
    char line[512], hms[32], speed[32];
    size_t len = format_done(p, "", line, sizeof(line));
    const double r = rate(p);
    if (r > 0.0) {
        format_rate(r, speed, sizeof(speed));
        len = append(line, sizeof(line), len, ", ETA %s, %s %s/s",
                     tw_progress_hms((p->total - p->done) / r, hms, sizeof(hms)), speed, p->unit);
    } else {
        len = append(line, sizeof(line), len, ", ETA not known yet");
    }
    len = append(line, sizeof(line), len, ", elapsed %s",
                 tw_progress_hms(now_s - p->start_s, hms, sizeof(hms)));
    /* A terminal's line keeps its figures and drops the note where the
     * note would not fit. */
    if (note && *note && (!p->tty || len + 2 + strlen(note) < p->columns))
        len = append(line, sizeof(line), len, "; %s", note);
    if (p->tty)
        show(p, line, len);
    else
        fprintf(p->out, "%s\n", line);
    fflush(p->out);
    p->printed = true;
    p->last_print_s = now_s;
}

void tw_progress_update(struct tw_progress *p, double done, const char *note)
{
    if (!p->quiet)
        tw_progress_update_at(p, done, note, tw_progress_now_s());
}

void tw_progress_clear(struct tw_progress *p)
{
    if (p->quiet || !p->tty || !p->printed)
        return;
    fprintf(p->out, "\r%*s\r", (int)p->shown, "");
    fflush(p->out);
    p->printed = false;
    p->shown = 0;
}

void tw_progress_finish_at(struct tw_progress *p, double now_s)
{
    if (p->quiet || !p->printed)
        return;
    if (p->tty) {
        fprintf(p->out, "\r%*s\r", (int)p->shown, "");
    } else {
        char line[512], hms[32], speed[32];
        const bool complete = p->done >= p->total;
        size_t len = format_done(p, complete ? "" : "stopped at ", line, sizeof(line));
        len = append(line, sizeof(line), len, ", %s %s", complete ? "done in" : "after",
                     tw_progress_hms(now_s - p->start_s, hms, sizeof(hms)));
        const double r = rate(p);
        if (r > 0.0) {
            format_rate(r, speed, sizeof(speed));
            append(line, sizeof(line), len, ", %s %s/s", speed, p->unit);
        }
        fprintf(p->out, "%s\n", line);
    }
    fflush(p->out);
    p->printed = false;
    p->shown = 0;
}

void tw_progress_finish(struct tw_progress *p)
{
    if (!p->quiet)
        tw_progress_finish_at(p, tw_progress_now_s());
}
