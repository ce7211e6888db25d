/*
 * The progress line of the tileworld programs' long runs (walk, bench,
 * memtest): how much is done of the total, the percentage, the rate and the
 * time left, on stderr only, never on stdout.
 *
 * On a terminal (stderr is a TTY) it is one line rewritten in place with a
 * carriage return, at most four times a second, cut to the terminal's width
 * and cleared when the run finishes. Anywhere else (a pipe, a file, a CI log)
 * it is a plain line every TW_PROGRESS_INTERVAL_S seconds of wall time (the
 * environment variable, a decimal number of seconds from 0 to 86400; default
 * 10; 0: a line at every update), none for a run shorter than that, and never
 * a carriage return; a run that printed a line ends with a last one saying
 * how long it took. Quiet: nothing at all.
 *
 * The rate, and from it the time left, is measured from the first update on:
 * what comes before it (a first frame's shader compilation, a world's first
 * tiles) is not counted in the rate, only in the time elapsed.
 *
 * Not thread-safe: one owner, the thread that runs the work.
 */
#ifndef TW_TOOLS_PROGRESS_H
#define TW_TOOLS_PROGRESS_H

#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>

/* The environment variable of the plain lines' interval, in seconds. */
#define TW_PROGRESS_INTERVAL_ENV "TW_PROGRESS_INTERVAL_S"
/* Its default. */
#define TW_PROGRESS_INTERVAL_DEFAULT_S 10.0

/* The state of one progress line; caller storage, filled by
 * tw_progress_init(). The fields are visible so that a test can set the
 * output, the mode and the interval after init. */
struct tw_progress {
    FILE *out;              /* stderr; borrowed */
    char label[160];        /* the run's name (its output folder), escaped */
    const char *unit;       /* "frames", "m": a string literal or borrowed for the run */
    double total;           /* in unit, > 0 */
    int decimals;           /* digits after the point of done and total */
    bool quiet;             /* nothing is printed */
    bool tty;               /* a line rewritten in place; else plain lines */
    double interval_s;      /* plain lines: seconds between lines */
    unsigned columns;       /* terminal: the line's room, in characters */
    double start_s;         /* monotonic seconds at init */
    double first_s;         /* at the first update, and done then: the rate's origin */
    double first_done;
    bool started;           /* an update came */
    double done;            /* the last update's, and its time */
    double done_s;
    double last_print_s;    /* when a line was last printed */
    size_t shown;           /* terminal: characters of the line now on screen */
    bool printed;           /* a line was printed */
};

/* Starts a progress line for total units (total > 0): label names the run
 * (copied, escaped, cut to fit), unit what is counted ("frames"; borrowed,
 * must outlive p), decimals the digits shown after the point. Reads whether
 * stderr is a terminal, its width and TW_PROGRESS_INTERVAL_S; a value that is
 * not a number from 0 to 86400 is said in one warning line (unless quiet) and
 * the default is kept. Prints nothing. */
void tw_progress_init(struct tw_progress *p, const char *label, double total, const char *unit,
                      int decimals, bool quiet);

/* done units of total are done (done is clamped to [0, total]); note, if not
 * NULL, is added at the end of the line ("83.1 ms/frame"; copied). Prints
 * when it is time to (see above). */
void tw_progress_update(struct tw_progress *p, double done, const char *note);

/* Erases a terminal's line so that other text can be printed; the next
 * update draws it again. Nothing for plain lines. */
void tw_progress_clear(struct tw_progress *p);

/* tw_progress_update() at the monotonic time now_s (seconds, as
 * tw_progress_now_s()): for tests. */
void tw_progress_update_at(struct tw_progress *p, double done, const char *note, double now_s);

/* Ends the line: on a terminal clears it; plain lines end with one saying the
 * time taken, if a line was printed. Safe to call twice and after a failed
 * run (it then says where the run stopped). */
void tw_progress_finish(struct tw_progress *p);

/* tw_progress_finish() at the monotonic time now_s: for tests. */
void tw_progress_finish_at(struct tw_progress *p, double now_s);

/* Monotonic seconds. */
double tw_progress_now_s(void);

/* Writes seconds as H:MM:SS (hours unbounded, rounded to the second; a
 * negative or non-finite value as "-:--:--") into out. Returns out. */
char *tw_progress_hms(double seconds, char *out, size_t out_size);

#endif
