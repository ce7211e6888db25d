/*
 * The assertion of the C test programs: a failed check prints file, line and
 * condition, is counted, and the test goes on (so one run reports every
 * failure). main() ends with check_summary().
 */
#ifndef TW_TESTS_CHECK_H
#define TW_TESTS_CHECK_H

#include <stdio.h>

static int failures;

#define CHECK(cond) \
    do { \
        if (!(cond)) { \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond); \
            failures++; \
        } \
    } while (0)

#endif
