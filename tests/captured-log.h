/*
 * A logger for the tests that expect a refusal: it counts the error messages
 * and keeps the last one, for the test to look for the file, the place and
 * the reason in it. Give it as {capture, &log} where a struct tw_log goes.
 */
#ifndef TW_TESTS_CAPTURED_LOG_H
#define TW_TESTS_CAPTURED_LOG_H

#include <stdio.h>

#include "tileworld/tiles.h"

struct captured_log {
    char last[2048];
    unsigned errors;
};

static inline void capture(void *user, enum tw_log_level level, const char *msg)
{
    struct captured_log *c = user;
    if (level == TW_LOG_ERROR) {
        c->errors++;
        snprintf(c->last, sizeof(c->last), "%s", msg);
    }
}

/* The same for loggers called from several threads (a provider's workers
 * next to the render thread): counted under a lock, which the reader takes
 * too. TW_TEST_VERBOSE in the environment prints every error as well.
 * Give it as {log_line, &lines}, lines = {.lock = PTHREAD_MUTEX_INITIALIZER}. */
#include <pthread.h>
#include <stdlib.h>

struct log_lines {
    pthread_mutex_t lock;
    unsigned errors;
    char last[512];
};

static inline void log_line(void *user, enum tw_log_level level, const char *msg)
{
    struct log_lines *l = user;
    if (level != TW_LOG_ERROR)
        return;
    pthread_mutex_lock(&l->lock);
    l->errors++;
    snprintf(l->last, sizeof(l->last), "%s", msg);
    if (getenv("TW_TEST_VERBOSE"))
        fprintf(stderr, "log: %s\n", msg);
    pthread_mutex_unlock(&l->lock);
}

#endif
