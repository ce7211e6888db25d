/*
 * A watchdog for the tests of calls that must never block (a FIFO opened as
 * a file): if the guarded call does not return within the time given, the
 * test says what it was blocked on and exits 1, rather than hanging until
 * meson's timeout.
 */
#ifndef TW_TESTS_WATCHDOG_H
#define TW_TESTS_WATCHDOG_H

#include <signal.h>
#include <string.h>
#include <unistd.h>

static const char *watchdog_message;
static size_t watchdog_length;

static void watchdog_fired(int sig)
{
    (void)sig;
    /* Only async-signal-safe calls here: write and _exit. */
    if (write(2, watchdog_message, watchdog_length) < 0)
        _exit(1);
    _exit(1);
}

/* message: the whole line, newline included. */
static void watchdog_arm(unsigned seconds, const char *message)
{
    watchdog_message = message;
    watchdog_length = strlen(message);
    signal(SIGALRM, watchdog_fired);
    alarm(seconds);
}

static void watchdog_disarm(void)
{
    alarm(0);
}

#endif
