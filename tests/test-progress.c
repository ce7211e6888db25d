/* The progress line (tools/progress.h) on a made-up clock, into a temporary
 * file: plain lines only once the interval has passed (none for a shorter
 * run), never a carriage return; a terminal's line rewritten in place and
 * cleared; the rate and the time left measured from the first update, so a
 * slow first frame does not skew them; quiet prints nothing; H:MM:SS. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tools/progress.h"
#include "tests/check.h"

/* What was written to f since it was opened, in text (size bytes). */
static const char *contents(FILE *f, char *text, size_t size)
{
    fflush(f);
    const long end = ftell(f);
    rewind(f);
    const size_t n = fread(text, 1, size - 1, f);
    text[n] = '\0';
    fseek(f, end, SEEK_SET);
    return text;
}

static int count_char(const char *s, char c)
{
    int n = 0;
    for (; *s; s++)
        n += *s == c;
    return n;
}

/* A progress line of total frames into a new temporary file, started at 0 s. */
static FILE *start(struct tw_progress *p, double total, bool tty, double interval_s, bool quiet)
{
    tw_progress_init(p, "out/walk", total, "frames", 0, quiet);
    FILE *f = tmpfile();
    if (!f) {
        perror("tmpfile");
        exit(1);
    }
    p->out = f;
    p->tty = tty;
    p->interval_s = interval_s;
    p->columns = 80;
    p->start_s = 0.0;
    p->last_print_s = 0.0;
    return f;
}

static void test_hms(void)
{
    char t[32];
    CHECK(strcmp(tw_progress_hms(0.0, t, sizeof(t)), "0:00:00") == 0);
    CHECK(strcmp(tw_progress_hms(59.6, t, sizeof(t)), "0:01:00") == 0);
    CHECK_MSG(strcmp(tw_progress_hms(3 * 3600 + 25 * 60 + 7, t, sizeof(t)), "3:25:07") == 0, "%s", t);
    CHECK_MSG(strcmp(tw_progress_hms(100 * 3600.0, t, sizeof(t)), "100:00:00") == 0, "%s", t);
    CHECK(strcmp(tw_progress_hms(-1.0, t, sizeof(t)), "-:--:--") == 0);
    CHECK(strcmp(tw_progress_hms(INFINITY, t, sizeof(t)), "-:--:--") == 0);
}

/* Plain lines: one every 10 s of wall time, the first after 10 s. */
static void test_plain(void)
{
    struct tw_progress p;
    char text[4096];
    FILE *f = start(&p, 300, false, 10.0, false);
    /* A slow first frame (5 s: shaders), then a frame a second. */
    tw_progress_update_at(&p, 1, NULL, 5.0);
    for (int k = 2; k <= 5; k++)
        tw_progress_update_at(&p, k, NULL, 5.0 + (k - 1));
    CHECK_MSG(contents(f, text, sizeof(text))[0] == '\0', "before 10 s: '%s'", text);
    tw_progress_update_at(&p, 6, "9.9 ms/frame", 10.0);
    contents(f, text, sizeof(text));
    CHECK_MSG(count_char(text, '\n') == 1, "'%s'", text);
    /* 5 frames in the 5 s since the first: 1 frame/s, 294 left. */
    CHECK_MSG(strstr(text, "out/walk: 6/300 frames (2.0 %), ETA 0:04:54, 1 frames/s, "
                           "elapsed 0:00:10; 9.9 ms/frame\n") != NULL, "'%s'", text);
    /* Not again before 10 s more. */
    tw_progress_update_at(&p, 10, NULL, 19.9);
    CHECK(count_char(contents(f, text, sizeof(text)), '\n') == 1);
    tw_progress_update_at(&p, 11, NULL, 20.0);
    CHECK(count_char(contents(f, text, sizeof(text)), '\n') == 2);
    tw_progress_update_at(&p, 300, NULL, 25.0);
    tw_progress_finish_at(&p, 25.0);
    contents(f, text, sizeof(text));
    CHECK_MSG(strstr(text, "out/walk: 300/300 frames (100.0 %), done in 0:00:25") != NULL, "'%s'",
              text);
    CHECK_MSG(strchr(text, '\r') == NULL, "a carriage return in plain lines: '%s'", text);
    /* A second finish says nothing more. */
    const size_t before = strlen(text);
    tw_progress_finish_at(&p, 26.0);
    CHECK(strlen(contents(f, text, sizeof(text))) == before);
    fclose(f);

    /* A run shorter than the interval prints nothing at all. */
    f = start(&p, 50, false, 10.0, false);
    for (int k = 1; k <= 50; k++)
        tw_progress_update_at(&p, k, NULL, 0.1 * k);
    tw_progress_finish_at(&p, 5.0);
    CHECK_MSG(contents(f, text, sizeof(text))[0] == '\0', "a 5 s run printed '%s'", text);
    fclose(f);

    /* Interval 0: a line at every update; a run that stops early says so. */
    f = start(&p, 4, false, 0.0, false);
    tw_progress_update_at(&p, 1, NULL, 1.0);
    tw_progress_update_at(&p, 2, NULL, 2.0);
    tw_progress_finish_at(&p, 2.4);
    contents(f, text, sizeof(text));
    CHECK_MSG(count_char(text, '\n') == 3, "'%s'", text);
    CHECK_MSG(strstr(text, "1/4 frames (25.0 %), ETA not known yet") != NULL, "'%s'", text);
    CHECK_MSG(strstr(text, "stopped at 2/4 frames (50.0 %), after 0:00:02, 1 frames/s\n") != NULL,
              "'%s'", text);
    fclose(f);
}

/* A terminal: every line begins with a carriage return, none ends in a
 * newline, at most four a second, and the last is cleared with spaces. */
static void test_tty(void)
{
    struct tw_progress p;
    char text[4096];
    FILE *f = start(&p, 100, true, 10.0, false);
    for (int k = 1; k <= 100; k++)
        tw_progress_update_at(&p, k, "a note", 0.01 * k);
    contents(f, text, sizeof(text));
    CHECK_MSG(count_char(text, '\r') == 4, "1 s of updates drew %d lines: '%s'",
              count_char(text, '\r'), text);
    CHECK(strchr(text, '\n') == NULL);
    CHECK(text[0] == '\r');
    const size_t drawn = strlen(text);
    tw_progress_finish_at(&p, 1.0);
    contents(f, text, sizeof(text));
    CHECK_MSG(strchr(text, '\n') == NULL, "'%s'", text);
    /* The clearing: \r, as many spaces as the last line, \r. */
    const char *tail = text + drawn;
    CHECK_MSG(tail[0] == '\r' && tail[strlen(tail) - 1] == '\r' &&
              strspn(tail + 1, " ") == strlen(tail) - 2 && strlen(tail) > 20, "'%s'", tail);
    fclose(f);

    /* A line longer than the terminal is cut to its width, the note first. */
    f = start(&p, 100, true, 10.0, false);
    p.columns = 40;
    tw_progress_update_at(&p, 1, "a note that does not fit", 1.0);
    contents(f, text, sizeof(text));
    CHECK_MSG(strlen(text) <= 40 && strstr(text, "note") == NULL, "'%s'", text);
    fclose(f);
}

static void test_quiet(void)
{
    struct tw_progress p;
    char text[256];
    FILE *f = start(&p, 10, false, 0.0, true);
    for (int k = 1; k <= 10; k++)
        tw_progress_update_at(&p, k, NULL, k);
    tw_progress_finish_at(&p, 11.0);
    CHECK_MSG(contents(f, text, sizeof(text))[0] == '\0', "quiet printed '%s'", text);
    fclose(f);
}

int main(void)
{
    test_hms();
    test_plain();
    test_tty();
    test_quiet();
    return check_summary("test-progress");
}
