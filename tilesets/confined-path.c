/* Opening a relative file name beneath a folder (confined-path.h). */
/* O_PATH, syscall() and SYS_openat2 are Linux interfaces. */
#define _GNU_SOURCE
#include "tilesets/confined-path.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <unistd.h>
#if defined(__linux__)
#include <linux/openat2.h>
#endif

#include "tileworld/tiles.h"

#ifndef O_PATH
#define O_PATH O_RDONLY
#endif

#define MAX_LINKS 40    /* the kernel's own limit */
#define MAX_DEPTH 256   /* folders deep */

static const char outside[] = "resolves outside the document's folder (through a symbolic link)";

static bool is_alpha(char c)
{
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z');
}

static bool is_digit(char c)
{
    return c >= '0' && c <= '9';
}

/* RFC 3986: scheme = ALPHA *( ALPHA / DIGIT / "+" / "-" / "." ) ":" */
static bool has_scheme(const char *s)
{
    if (!is_alpha(s[0]))
        return false;
    size_t k = 1;
    while (is_alpha(s[k]) || is_digit(s[k]) || s[k] == '+' || s[k] == '-' || s[k] == '.')
        k++;
    return s[k] == ':';
}

/* Whether the ".." components of rel ever climb above its starting folder. */
static bool climbs_out(const char *rel)
{
    long depth = 0;
    const char *p = rel;
    while (*p) {
        const char *end = strchr(p, '/');
        size_t n = end ? (size_t)(end - p) : strlen(p);
        if (n == 2 && p[0] == '.' && p[1] == '.') {
            if (--depth < 0)
                return true;
        } else if (n > 0 && !(n == 1 && p[0] == '.')) {
            depth++;
        }
        p += n;
        if (*p == '/')
            p++;
    }
    return false;
}

char *tw_confined_path_dirname(const char *path)
{
    const char *slash = strrchr(path, '/');
    if (!slash) {
        char *dot = malloc(2);
        if (dot)
            memcpy(dot, ".", 2);
        return dot;
    }
    size_t n = (size_t)(slash - path);
    if (n == 0)
        n = 1; /* "/file" lives in "/" */
    char *dir = malloc(n + 1);
    if (dir) {
        memcpy(dir, path, n);
        dir[n] = '\0';
    }
    return dir;
}

/* The checks on the name as text. */
static int check_name(const char *rel, const char **reason)
{
    if (!rel || !rel[0]) {
        *reason = "is empty";
        return TW_ERR_FORMAT;
    }
    if (rel[0] == '/') {
        *reason = "is an absolute path: only paths relative to the document's folder are allowed";
        return TW_ERR_FORMAT;
    }
    if (has_scheme(rel)) {
        *reason = "is a URI: only plain relative file paths are allowed";
        return TW_ERR_FORMAT;
    }
    if (strchr(rel, '\\')) {
        *reason = "contains a backslash: separate folders with /";
        return TW_ERR_FORMAT;
    }
    if (climbs_out(rel)) {
        *reason = "climbs out of the document's folder with ..";
        return TW_ERR_FORMAT;
    }
    return TW_OK;
}

static int errno_reason(int e, const char **reason)
{
    switch (e) {
    case ENOENT:
        *reason = "does not exist";
        break;
    case EXDEV:
        *reason = outside;
        return TW_ERR_FORMAT;
    case ELOOP:
        *reason = "goes through too many symbolic links, or a /proc magic link";
        return TW_ERR_FORMAT;
    case ENOTDIR:
        *reason = "has a component that is not a folder";
        break;
    case ENOMEM:
        *reason = "cannot be opened: out of memory";
        return TW_ERR_NOMEM;
    default:
        *reason = strerror(e);
        break;
    }
    return TW_ERR_IO;
}

/* Checks what was opened: a regular file (want_dir false) or a folder. */
static int check_opened(int dir_fd, int fd, bool want_dir, const char **reason)
{
    struct stat st;
    if (fstat(fd, &st) != 0)
        return errno_reason(errno, reason);
    if (want_dir) {
        if (!S_ISDIR(st.st_mode)) {
            *reason = "has a component that is not a folder";
            return TW_ERR_IO;
        }
        return TW_OK;
    }
    if (S_ISDIR(st.st_mode)) {
        struct stat top;
        const bool same = fstat(dir_fd, &top) == 0 && top.st_dev == st.st_dev &&
                          top.st_ino == st.st_ino;
        *reason = same ? "is the document's folder, not a file" : "is a folder, not a file";
        return TW_ERR_FORMAT;
    }
    if (!S_ISREG(st.st_mode)) {
        *reason = "is not a regular file";
        return TW_ERR_IO;
    }
    return TW_OK;
}

static const int file_flags = O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY;
static const int dir_flags = O_PATH | O_DIRECTORY | O_CLOEXEC;

/* openat2(): 1 if it answered (*fd, or -1 with errno), 0 if the kernel does
 * not have it. */
static int open_beneath_kernel(int dir_fd, const char *rel, bool want_dir, int *fd)
{
#if defined(__linux__) && defined(SYS_openat2) && defined(RESOLVE_BENEATH)
    struct open_how how;
    memset(&how, 0, sizeof(how));
    how.flags = (uint64_t)(want_dir ? dir_flags : file_flags);
    how.resolve = RESOLVE_BENEATH | RESOLVE_NO_MAGICLINKS;
    for (int attempt = 0; attempt < 16; attempt++) {
        const long r = syscall(SYS_openat2, dir_fd, rel, &how, sizeof(how));
        if (r >= 0) {
            *fd = (int)r;
            return 1;
        }
        /* EAGAIN: a rename raced with the lookup's ".." checks; retry. */
        if (errno != EAGAIN && errno != EINTR)
            break;
    }
    /* ENOSYS: the kernel lacks it; EPERM: a seccomp filter (older
     * container runtimes) refuses system calls it does not know. The walk
     * below gives the real answer either way. */
    if (errno == ENOSYS || errno == EPERM)
        return 0;
    *fd = -1;
    return 1;
#else
    (void)dir_fd;
    (void)rel;
    (void)want_dir;
    (void)fd;
    return 0;
#endif
}

/* The walk: one component at a time beneath dir_fd, never following a
 * link in the kernel (O_NOFOLLOW), following each one here. */
static int open_beneath_walk(int dir_fd, const char *rel, bool want_dir, int *out_fd,
                             const char **reason)
{
    int stack[MAX_DEPTH];
    int depth = 0, links = 0, err = TW_OK;
    char *path = malloc(strlen(rel) + 1);
    if (!path) {
        *reason = "cannot be opened: out of memory";
        return TW_ERR_NOMEM;
    }
    strcpy(path, rel);
    size_t pos = 0;
    for (;;) {
        while (path[pos] == '/')
            pos++;
        const int cur = depth ? stack[depth - 1] : dir_fd;
        if (!path[pos]) {
            /* Every component was a folder. */
            if (want_dir) {
                const int fd = fcntl(cur, F_DUPFD_CLOEXEC, 0);
                if (fd < 0) {
                    err = errno_reason(errno, reason);
                    goto out;
                }
                *out_fd = fd;
                goto out;
            }
            *reason = depth ? "is a folder, not a file" : "is the document's folder, not a file";
            err = TW_ERR_FORMAT;
            goto out;
        }
        size_t end = pos;
        while (path[end] && path[end] != '/')
            end++;
        size_t next = end;
        while (path[next] == '/')
            next++;
        const bool last = !path[next];
        char name[NAME_MAX + 1];
        const size_t len = end - pos;
        if (len > NAME_MAX) {
            err = errno_reason(ENAMETOOLONG, reason);
            goto out;
        }
        memcpy(name, path + pos, len);
        name[len] = '\0';
        pos = next;
        if (strcmp(name, ".") == 0)
            continue;
        if (strcmp(name, "..") == 0) {
            if (depth == 0) {
                *reason = outside;
                err = TW_ERR_FORMAT;
                goto out;
            }
            close(stack[--depth]);
            continue;
        }
        bool is_link = false;
        if (last && !want_dir) {
            const int fd = openat(cur, name, file_flags | O_NOFOLLOW);
            if (fd >= 0) {
                struct stat st;
                if (fstat(fd, &st) == 0 && S_ISDIR(st.st_mode) && depth < MAX_DEPTH) {
                    stack[depth++] = fd;  /* "is a folder", said above */
                    continue;
                }
                if ((err = check_opened(cur, fd, false, reason))) {
                    close(fd);
                    goto out;
                }
                *out_fd = fd;
                goto out;
            }
            if (errno != ELOOP) {
                err = errno_reason(errno, reason);
                goto out;
            }
            is_link = true;
        } else {
            const int fd = openat(cur, name, O_PATH | O_NOFOLLOW | O_CLOEXEC);
            if (fd < 0) {
                err = errno_reason(errno, reason);
                goto out;
            }
            struct stat st;
            if (fstat(fd, &st) != 0) {
                err = errno_reason(errno, reason);
                close(fd);
                goto out;
            }
            if (S_ISLNK(st.st_mode)) {
                close(fd);
                is_link = true;
            } else if (!S_ISDIR(st.st_mode)) {
                close(fd);
                *reason = "has a component that is not a folder";
                err = TW_ERR_IO;
                goto out;
            } else if (depth == MAX_DEPTH) {
                close(fd);
                *reason = "is nested too deeply";
                err = TW_ERR_LIMIT;
                goto out;
            } else {
                stack[depth++] = fd;
            }
        }
        if (!is_link)
            continue;
        /* A symbolic link: its target replaces it, relative to cur. */
        if (++links > MAX_LINKS) {
            err = errno_reason(ELOOP, reason);
            goto out;
        }
        char target[PATH_MAX];
        const ssize_t n = readlinkat(cur, name, target, sizeof(target) - 1);
        if (n < 0) {
            err = errno_reason(errno, reason);
            goto out;
        }
        target[n] = '\0';
        if (n == 0 || target[0] == '/') {
            *reason = outside;
            err = TW_ERR_FORMAT;
            goto out;
        }
        const size_t rest = strlen(path + pos);
        char *joined = malloc((size_t)n + 1 + rest + 1);
        if (!joined) {
            *reason = "cannot be opened: out of memory";
            err = TW_ERR_NOMEM;
            goto out;
        }
        memcpy(joined, target, (size_t)n);
        joined[n] = '/';
        memcpy(joined + n + 1, path + pos, rest + 1);
        if (!rest)
            joined[n] = '\0';
        free(path);
        path = joined;
        pos = 0;
    }
out:
    while (depth > 0)
        close(stack[--depth]);
    free(path);
    return err;
}

static int open_beneath(int dir_fd, const char *rel, bool want_dir, enum tw_confined_mode mode,
                        int *out_fd, const char **reason)
{
    int fd = -1;
    if (mode == TW_CONFINED_AUTO && open_beneath_kernel(dir_fd, rel, want_dir, &fd)) {
        if (fd < 0)
            return errno_reason(errno, reason);
        const int err = check_opened(dir_fd, fd, want_dir, reason);
        if (err) {
            close(fd);
            return err;
        }
        *out_fd = fd;
        return TW_OK;
    }
    return open_beneath_walk(dir_fd, rel, want_dir, out_fd, reason);
}

/* What both opens check first: *reason cleared (when reason is NULL,
 * *reason is pointed at a place that nobody reads), out_fd given and
 * cleared, rel a name they take. */
static int open_begin(const char *rel, int *out_fd, const char ***reason)
{
    static const char *unused;
    if (!*reason)
        *reason = &unused;
    **reason = NULL;
    if (!out_fd) {
        **reason = "cannot be opened (caller's bug)";
        return TW_ERR_INVALID;
    }
    *out_fd = -1;
    return check_name(rel, *reason);
}

int tw_confined_open(int dir_fd, const char *rel, enum tw_confined_mode mode, int *out_fd,
                     const char **reason)
{
    int err = open_begin(rel, out_fd, &reason);
    if (err)
        return err;
    return open_beneath(dir_fd, rel, false, mode, out_fd, reason);
}

int tw_confined_open_parent(int dir_fd, const char *rel, enum tw_confined_mode mode,
                            int *out_fd, const char **reason)
{
    int err = open_begin(rel, out_fd, &reason);
    if (err)
        return err;
    const char *slash = strrchr(rel, '/');
    if (!slash) {
        const int fd = fcntl(dir_fd, F_DUPFD_CLOEXEC, 0);
        if (fd < 0)
            return errno_reason(errno, reason);
        *out_fd = fd;
        return TW_OK;
    }
    const size_t n = (size_t)(slash - rel);
    char *dir = malloc(n + 2);
    if (!dir) {
        *reason = "cannot be opened: out of memory";
        return TW_ERR_NOMEM;
    }
    memcpy(dir, rel, n);
    dir[n] = '\0';
    if (n == 0)
        strcpy(dir, ".");
    err = open_beneath(dir_fd, dir, true, mode, out_fd, reason);
    free(dir);
    return err;
}

int tw_confined_open_user(const char *path, int *out_fd, char *why, size_t why_size)
{
    *out_fd = -1;
    const int fd = open(path, O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
    if (fd < 0) {
        if (errno == ENOENT)
            snprintf(why, why_size, "no such file");
        else
            snprintf(why, why_size, "cannot open: %s", strerror(errno));
        return TW_ERR_IO;
    }
    struct stat st;
    if (fstat(fd, &st) != 0) {
        snprintf(why, why_size, "cannot stat: %s", strerror(errno));
        close(fd);
        return TW_ERR_IO;
    }
    if (!S_ISREG(st.st_mode)) {
        snprintf(why, why_size, "is not a regular file (a %s)",
                 S_ISFIFO(st.st_mode)                        ? "FIFO"
                 : S_ISDIR(st.st_mode)                       ? "folder"
                 : S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) ? "device"
                 : S_ISSOCK(st.st_mode)                      ? "socket"
                                                             : "special file");
        close(fd);
        return TW_ERR_IO;
    }
    *out_fd = fd;
    return TW_OK;
}

int tw_confined_open_folder(const char *path)
{
    return open(path, O_PATH | O_DIRECTORY | O_CLOEXEC);
}

int tw_confined_open_folder_of(const char *path)
{
    char *dir = tw_confined_path_dirname(path);
    if (!dir) {
        errno = ENOMEM;
        return -1;
    }
    const int fd = tw_confined_open_folder(dir);
    const int e = errno;
    free(dir);
    errno = e;
    return fd;
}

int tw_confined_read(int fd, uint64_t limit, uint8_t **data, size_t *size, char *why,
                     size_t why_size)
{
    *data = NULL;
    *size = 0;
    struct stat st;
    if (fstat(fd, &st) != 0) {
        snprintf(why, why_size, "cannot stat: %s", strerror(errno));
        return TW_ERR_IO;
    }
    if (!S_ISREG(st.st_mode)) {
        snprintf(why, why_size, "is not a regular file");
        return TW_ERR_IO;
    }
    if (st.st_size < 0 || (uint64_t)st.st_size > limit) {
        snprintf(why, why_size, "is %lld bytes, more than the limit of %llu bytes",
                 (long long)st.st_size, (unsigned long long)limit);
        return TW_ERR_LIMIT;
    }
    /* Read to the end, not to st_size: the file may change meanwhile. */
    size_t cap = (size_t)st.st_size + 1, n = 0;
    uint8_t *buf = malloc(cap);
    if (!buf) {
        snprintf(why, why_size, "out of memory reading %zu bytes", cap - 1);
        return TW_ERR_NOMEM;
    }
    int err = TW_OK;
    for (;;) {
        if (n == cap) {
            if (cap > limit) {
                snprintf(why, why_size, "grew beyond the limit of %llu bytes while it was read",
                         (unsigned long long)limit);
                err = TW_ERR_LIMIT;
                break;
            }
            uint8_t *grown = realloc(buf, cap * 2);
            if (!grown) {
                snprintf(why, why_size, "out of memory reading %zu bytes", cap * 2);
                err = TW_ERR_NOMEM;
                break;
            }
            buf = grown;
            cap *= 2;
        }
        const ssize_t r = read(fd, buf + n, cap - n);
        if (r < 0 && (errno == EINTR || errno == EAGAIN))
            continue;
        if (r < 0) {
            snprintf(why, why_size, "cannot read: %s", strerror(errno));
            err = TW_ERR_IO;
            break;
        }
        if (r == 0)
            break;
        n += (size_t)r;
    }
    if (!err && n > limit) {
        snprintf(why, why_size, "grew beyond the limit of %llu bytes while it was read",
                 (unsigned long long)limit);
        err = TW_ERR_LIMIT;
    }
    if (err) {
        free(buf);
        return err;
    }
    *data = buf;
    *size = n;
    return TW_OK;
}
