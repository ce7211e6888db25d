/*
 * --gl and --gpu, the options of the tileworld commands that make a headless
 * OpenGL context (walk, bench, info, memtest), and the context they ask for.
 * TW_GPU in the environment picks the EGL device as --gpu does; --gpu wins.
 */
#ifndef TW_TOOLS_GLCONTEXT_H
#define TW_TOOLS_GLCONTEXT_H

#include <stdbool.h>
#include <stdint.h>

#include "tileworld/context.h"
#include "tools/cli.h"

enum {
    TW_GL_OPT_API = TW_CLI_OPT_PROGRAM + 200,
    TW_GL_OPT_GPU,
};

/* Entries of a program's struct option table. */
#define TW_GL_OPTIONS \
    {"gl", required_argument, NULL, TW_GL_OPT_API}, \
    {"gpu", required_argument, NULL, TW_GL_OPT_GPU}

/* The lines of --help that describe them. */
extern const char tw_gl_usage[];

/* Applies --gl or --gpu to s; false when opt is neither. Bad values end the
 * program as tw_cli_fail() does. */
bool tw_gl_option(struct tw_context_settings *s, int opt, const char *name, const char *v);

/* Creates the context of s at width x height, with TW_GPU applied when no
 * --gpu was given; on failure the library's one line has been printed
 * through log, and the caller exits with status 1. */
int tw_gl_context_create(const struct tw_context_settings *s, uint32_t width, uint32_t height,
                         const struct tw_log *log, struct tw_context **out);

#endif
