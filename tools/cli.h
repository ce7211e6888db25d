/*
 * Command-line values for the tileworld programs (tileworld, tileworld-view).
 * Bad input is the user's: each parser ends the program with exit status
 * TW_CLI_EXIT_USAGE and one line "PROGRAM: PLACE: reason" on stderr, never a
 * crash. Linked into the executables only, never into a library: it exits.
 */
#ifndef TW_RUNTIME_CLI_H
#define TW_RUNTIME_CLI_H

#include <stdint.h>
#include <stdnoreturn.h>

#include "tileworld/tiles.h"

#define TW_CLI_EXIT_USAGE 2

/* Prints "program: place: " and fmt with value for its one %s, then exits. */
noreturn void tw_cli_fail(const char *program, const char *place, const char *fmt,
                          const char *value);

/* A whole number in [lo, hi] (no sign, no spaces). */
uint64_t tw_cli_u64(const char *program, const char *opt, const char *s, uint64_t lo, uint64_t hi);
/* A signed 64-bit whole number. */
int64_t tw_cli_i64(const char *program, const char *opt, const char *s);
/* A finite number in [lo, hi]. */
float tw_cli_float(const char *program, const char *opt, const char *s, float lo, float hi);
/* WIDTHxHEIGHT, each in [16, 8192]. */
void tw_cli_size(const char *program, const char *opt, const char *s, uint32_t *w, uint32_t *h);
/* I,J within +-2^62 cells, where neighbour arithmetic cannot overflow. */
void tw_cli_cell(const char *program, const char *opt, const char *s, struct tw_cell *c);

#endif
