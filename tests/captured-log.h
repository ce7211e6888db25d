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

static void capture(void *user, enum tw_log_level level, const char *msg)
{
    struct captured_log *c = user;
    if (level == TW_LOG_ERROR) {
        c->errors++;
        snprintf(c->last, sizeof(c->last), "%s", msg);
    }
}

#endif
