/*
 * The programs' shared library (tools/cli.c), the parts a script cannot
 * reach:
 *   - tw_cli_escape(): control characters, C1 controls, bidirectional
 *     overrides and bytes that are not UTF-8 never reach a terminal, valid
 *     UTF-8 does, a backslash is doubled, and the output fits its buffer;
 *   - tw_cli_catch_crashes(): a child that crashes (SIGSEGV raised, a real
 *     fault, a stack overflow, SIGBUS) writes exactly one line, which names
 *     the address-space limit when there is one, and still dies of the
 *     signal; a handler installed before it is left alone. Skipped in a
 *     build with a sanitizer, whose own handler stays.
 */
#define _XOPEN_SOURCE 700

#include <limits.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "tests/check.h"
#include "tools/cli.h"

static void test_escape(void)
{
    char out[256];
    CHECK(strcmp(tw_cli_escape("plain", out, sizeof(out)), "plain") == 0);
    CHECK(strcmp(tw_cli_escape("a\x1b[31mb", out, sizeof(out)), "a\\x1b[31mb") == 0);
    CHECK(strcmp(tw_cli_escape("a\\b", out, sizeof(out)), "a\\\\b") == 0);
    /* An escape's text in the input is not an escape in the output. */
    CHECK(strcmp(tw_cli_escape("\\x1b", out, sizeof(out)), "\\\\x1b") == 0);
    CHECK(strcmp(tw_cli_escape("line\nnext\r\t", out, sizeof(out)), "line\\nnext\\r\\t") == 0);
    /* Right-to-left override (U+202E), isolate (U+2066), CSI as a C1
     * control (U+009B): escaped; UTF-8 text kept. */
    CHECK_MSG(strcmp(tw_cli_escape("evil\xe2\x80\xaetxt.exe", out, sizeof(out)),
                     "evil\\u202etxt.exe") == 0, "\"%s\"", out);
    CHECK(strcmp(tw_cli_escape("\xe2\x81\xa6x", out, sizeof(out)), "\\u2066x") == 0);
    CHECK(strcmp(tw_cli_escape("\xc2\x9b" "2J", out, sizeof(out)), "\\u009b2J") == 0);
    CHECK(strcmp(tw_cli_escape("caf\xc3\xa9 \xe2\x82\xac", out, sizeof(out)),
                 "caf\xc3\xa9 \xe2\x82\xac") == 0);
    /* Not UTF-8: a lone continuation byte, a cut sequence, an overlong form. */
    CHECK_MSG(strcmp(tw_cli_escape("\x9b\xff\xc3(\xc0\xaf", out, sizeof(out)),
                     "\\x9b\\xff\\xc3(\\xc0\\xaf") == 0, "\"%s\"", out);
    CHECK(strcmp(tw_cli_escape(NULL, out, sizeof(out)), "") == 0);
    /* Four bytes out per byte in at most: what callers size their buffers by. */
    char worst[65], four[4 * 64 + 1];
    memset(worst, 0x01, 64);
    worst[64] = '\0';
    tw_cli_escape(worst, four, sizeof(four));
    CHECK(strlen(four) == 4 * 64 && strstr(four, "...") == NULL);
    /* A cut fits, ends with "...", and never splits an escape. */
    char small[8];
    CHECK(strcmp(tw_cli_escape("abc\\def", small, sizeof(small)), "abc...") == 0);
    CHECK(strcmp(tw_cli_escape("\x1b\x1b\x1b", small, sizeof(small)), "\\x1b...") == 0);
    /* Nothing that drives a terminal survives any input. */
    unsigned bad = 0;
    for (int c = 1; c < 256; c++) {
        const char in[4] = {'x', (char)c, 'y', '\0'};
        tw_cli_escape(in, out, sizeof(out));
        for (const unsigned char *p = (const unsigned char *)out; *p; p++)
            bad += *p < 0x20 || *p >= 0x7f;   /* one byte >= 0x80 alone is not UTF-8 */
    }
    CHECK_MSG(bad == 0, "%u control bytes through", bad);
}

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || \
    __has_feature(memory_sanitizer)
#define SANITIZED 1
#endif
#endif

#ifndef SANITIZED
enum crash { RAISE_SEGV, FAULT, OVERFLOW, RAISE_BUS, HOST_HANDLER };

static void host_handler(int sig)
{
    (void)sig;
    _exit(42);
}

/* Recurses until the stack runs out (the test below never passes INT_MIN). */
static int deep(int n, volatile char *sink)
{
    volatile char pad[4096];
    pad[0] = (char)n;
    if (n == INT_MIN)
        return 0;
    *sink = pad[0];
    return deep(n + 1, pad) + pad[n & 1];
}

/* Runs a child that crashes as how says, with an address-space limit of
 * limit_mib (0: none); returns its wait status and its stderr in err. */
static int crash_child(enum crash how, unsigned long long limit_mib, char *err, size_t err_size)
{
    int fd[2];
    if (pipe(fd) != 0)
        return -1;
    fflush(NULL);
    const pid_t pid = fork();
    if (pid == 0) {
        dup2(fd[1], STDERR_FILENO);
        close(fd[0]);
        /* No core files from these. */
        const struct rlimit no_core = {0, 0};
        setrlimit(RLIMIT_CORE, &no_core);
        if (limit_mib) {
            /* Far above what the child uses: only the figure matters. */
            const struct rlimit as = {(rlim_t)limit_mib << 20, (rlim_t)limit_mib << 20};
            setrlimit(RLIMIT_AS, &as);
        }
        if (how == HOST_HANDLER)
            signal(SIGSEGV, host_handler);
        struct tw_cli c;
        tw_cli_init(&c, "tileworld");
        volatile char sink = 0;
        switch (how) {
        case RAISE_SEGV: case HOST_HANDLER: raise(SIGSEGV); break;
        case RAISE_BUS: raise(SIGBUS); break;
        case FAULT: {
            void *block = NULL;
            const long size = sysconf(_SC_PAGESIZE);
            if (posix_memalign(&block, (size_t)size, (size_t)size) == 0 &&
                mprotect(block, (size_t)size, PROT_NONE) == 0)
                ((volatile char *)block)[0] = 1;
            break;
        }
        case OVERFLOW: deep(1, &sink); break;
        }
        _exit(0);
    }
    close(fd[1]);
    size_t n = 0;
    ssize_t got;
    while (n + 1 < err_size && (got = read(fd[0], err + n, err_size - 1 - n)) > 0)
        n += (size_t)got;
    err[n] = '\0';
    close(fd[0]);
    int status = 0;
    if (pid < 0 || waitpid(pid, &status, 0) != pid)
        return -1;
    return status;
}

static bool one_line(const char *s)
{
    const char *nl = strchr(s, '\n');
    return nl && nl[1] == '\0';
}

static void test_crashes(void)
{
    char err[1024];
    /* Under a limit: the limit, the likely cause, what to do. */
    int st = crash_child(RAISE_SEGV, 65536, err, sizeof(err));
    CHECK_MSG(st != -1 && WIFSIGNALED(st) && WTERMSIG(st) == SIGSEGV, "status %#x", st);
    static const char limited[] = "tileworld: crashed (SIGSEGV) under an address-space limit "
                                  "of 65536 MiB (ulimit -v): most likely out of memory";
    CHECK_MSG(one_line(err) && strncmp(err, limited, sizeof(limited) - 1) == 0 &&
              strstr(err, "raise the limit"), "\"%s\"", err);
    printf("crash under a limit: %s", err);
    /* Without one: a bug. */
    st = crash_child(RAISE_SEGV, 0, err, sizeof(err));
    CHECK_MSG(st != -1 && WIFSIGNALED(st) && WTERMSIG(st) == SIGSEGV, "status %#x", st);
    CHECK_MSG(strcmp(err, "tileworld: crashed (SIGSEGV): this is a bug, please report it\n") == 0,
              "\"%s\"", err);
    printf("crash: %s", err);
    /* A real fault, which faults again once the handler returns. */
    st = crash_child(FAULT, 0, err, sizeof(err));
    CHECK_MSG(st != -1 && WIFSIGNALED(st) && WTERMSIG(st) == SIGSEGV && one_line(err) &&
              strstr(err, "crashed (SIGSEGV)"), "status %#x, \"%s\"", st, err);
    /* The stack ran out: the handler has a stack of its own. */
    st = crash_child(OVERFLOW, 0, err, sizeof(err));
    CHECK_MSG(st != -1 && WIFSIGNALED(st) && WTERMSIG(st) == SIGSEGV && one_line(err) &&
              strstr(err, "crashed (SIGSEGV)"), "status %#x, \"%s\"", st, err);
    st = crash_child(RAISE_BUS, 0, err, sizeof(err));
    CHECK_MSG(st != -1 && WIFSIGNALED(st) && WTERMSIG(st) == SIGBUS && one_line(err) &&
              strstr(err, "crashed (SIGBUS)"), "status %#x, \"%s\"", st, err);
    /* A handler of the host's stays. */
    st = crash_child(HOST_HANDLER, 0, err, sizeof(err));
    CHECK_MSG(st != -1 && WIFEXITED(st) && WEXITSTATUS(st) == 42 && err[0] == '\0',
              "status %#x, \"%s\"", st, err);
}
#endif

int main(void)
{
    test_escape();
#ifdef SANITIZED
    printf("crash handler: not installed under a sanitizer (its own handler reports), not "
           "tested\n");
#else
    test_crashes();
#endif
    return check_summary("test-tools-shared");
}
