/* Command-line values for the tileworld programs (cli.h). */
#include "tools/cli.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

noreturn void tw_cli_fail(const char *program, const char *place, const char *fmt,
                          const char *value)
{
    fprintf(stderr, "%s: %s: ", program, place);
    fprintf(stderr, fmt, value);
    fputc('\n', stderr);
    exit(TW_CLI_EXIT_USAGE);
}

uint64_t tw_cli_u64(const char *program, const char *opt, const char *s, uint64_t lo, uint64_t hi)
{
    char *end = NULL;
    errno = 0;
    if (!s || *s == '\0' || *s == '-' || *s == '+' || *s == ' ')
        tw_cli_fail(program, opt, "'%s' is not a non-negative whole number", s ? s : "");
    unsigned long long v = strtoull(s, &end, 10);
    if (*end != '\0')
        tw_cli_fail(program, opt, "'%s' is not a non-negative whole number", s);
    if (errno == ERANGE || v < lo || v > hi) {
        char msg[128];
        snprintf(msg, sizeof(msg), "'%%s' is out of range [%llu, %llu]", (unsigned long long)lo,
                 (unsigned long long)hi);
        tw_cli_fail(program, opt, msg, s);
    }
    return v;
}

int64_t tw_cli_i64(const char *program, const char *opt, const char *s)
{
    char *end = NULL;
    errno = 0;
    if (!s || *s == '\0' || *s == ' ')
        tw_cli_fail(program, opt, "'%s' is not a whole number", s ? s : "");
    long long v = strtoll(s, &end, 10);
    if (*end != '\0')
        tw_cli_fail(program, opt, "'%s' is not a whole number", s);
    if (errno == ERANGE)
        tw_cli_fail(program, opt, "'%s' does not fit in 64 bits", s);
    return v;
}

float tw_cli_float(const char *program, const char *opt, const char *s, float lo, float hi)
{
    char *end = NULL;
    errno = 0;
    if (!s || *s == '\0')
        tw_cli_fail(program, opt, "'%s' is not a number", "");
    double v = strtod(s, &end);
    if (*end != '\0' || end == s)
        tw_cli_fail(program, opt, "'%s' is not a number", s);
    if (!isfinite(v) || errno == ERANGE)
        tw_cli_fail(program, opt, "'%s' is not a finite number", s);
    if (v < lo || v > hi) {
        char msg[128];
        snprintf(msg, sizeof(msg), "'%%s' is out of range [%g, %g]", lo, hi);
        tw_cli_fail(program, opt, msg, s);
    }
    return (float)v;
}

/* Splits "A<sep>B" into first (copied, at most 31 characters) and *second. */
static void split_pair(const char *program, const char *opt, const char *s, char sep,
                       const char *form, char first[32], const char **second)
{
    const char *at = s ? strchr(s, sep) : NULL;
    const size_t n = at ? (size_t)(at - s) : 0;
    if (!at || n == 0 || n >= 32)
        tw_cli_fail(program, opt, form, s ? s : "");
    memcpy(first, s, n);
    first[n] = '\0';
    *second = at + 1;
}

void tw_cli_size(const char *program, const char *opt, const char *s, uint32_t *w, uint32_t *h)
{
    char first[32];
    const char *second;
    split_pair(program, opt, s, 'x', "'%s' is not of the form WIDTHxHEIGHT", first, &second);
    *w = (uint32_t)tw_cli_u64(program, opt, first, 16, 8192);
    *h = (uint32_t)tw_cli_u64(program, opt, second, 16, 8192);
}

void tw_cli_cell(const char *program, const char *opt, const char *s, struct tw_cell *c)
{
    char first[32];
    const char *second;
    split_pair(program, opt, s, ',', "'%s' is not of the form I,J", first, &second);
    c->i = tw_cli_i64(program, opt, first);
    c->j = tw_cli_i64(program, opt, second);
    /* Keep cells where neighbour arithmetic cannot overflow. */
    const int64_t limit = (int64_t)1 << 62;
    if (c->i > limit || c->i < -limit || c->j > limit || c->j < -limit)
        tw_cli_fail(program, opt, "'%s' lies outside +-2^62 cells", s);
}
