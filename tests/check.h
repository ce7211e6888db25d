/*
 * The assertion of the C test programs: a failed check prints file, line and
 * condition (and, from CHECK_MSG, what was found), is counted, and the test
 * goes on, so that one run reports every failure. main() ends with
 * `return check_summary("test-NAME");`.
 */
#ifndef TW_TESTS_CHECK_H
#define TW_TESTS_CHECK_H

#include <stdarg.h>
#include <stdio.h>

static int failures;
static int checks;

/* Counts and reports a failed check; fmt (printf's), if not NULL, says what
 * was found instead. */
#if defined(__GNUC__)
__attribute__((format(printf, 4, 5)))
#endif
static void check_failed(const char *file, int line, const char *cond, const char *fmt, ...)
{
    fprintf(stderr, "%s:%d: check failed: %s", file, line, cond);
    if (fmt) {
        va_list ap;
        va_start(ap, fmt);
        fputs(": ", stderr);
        vfprintf(stderr, fmt, ap);
        va_end(ap);
    }
    fputc('\n', stderr);
    failures++;
}

#define CHECK(cond) \
    do { \
        checks++; \
        if (!(cond)) \
            check_failed(__FILE__, __LINE__, #cond, NULL); \
    } while (0)

/* CHECK(cond) with a printf message after it, for the values a bare
 * condition does not show. */
#define CHECK_MSG(cond, ...) \
    do { \
        checks++; \
        if (!(cond)) \
            check_failed(__FILE__, __LINE__, #cond, __VA_ARGS__); \
    } while (0)

/* The last line of a test and its exit status: 0 if every check held. */
static int check_summary(const char *test)
{
    if (failures) {
        fprintf(stderr, "%s: %d of %d checks failed\n", test, failures, checks);
        return 1;
    }
    printf("%s: all %d checks passed\n", test, checks);
    return 0;
}

#endif
