/* Resolving a relative file name inside a folder (confined-path.h). */
/* realpath() is XSI, beyond the project-wide _POSIX_C_SOURCE. */
#define _XOPEN_SOURCE 700
#include "tilesets/confined-path.h"

#include <errno.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "tileworld/tiles.h"

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

int tw_confined_path_resolve(const char *dir, const char *rel, char **out, const char **reason)
{
    static const char *no_reason = "is invalid";
    const char *why = no_reason;
    int err = TW_ERR_INVALID;
    char *joined = NULL, *dir_real = NULL, *file_real = NULL;
    *out = NULL;

    if (!dir || !rel || !rel[0]) {
        why = "is empty";
        goto fail;
    }
    if (rel[0] == '/') {
        why = "is an absolute path: only paths relative to the document's folder are allowed";
        goto fail;
    }
    if (has_scheme(rel)) {
        why = "is a URI: only plain relative file paths are allowed";
        goto fail;
    }
    if (strchr(rel, '\\')) {
        why = "contains a backslash: separate folders with /";
        goto fail;
    }
    if (climbs_out(rel)) {
        why = "climbs out of the document's folder with ..";
        goto fail;
    }

    const size_t nd = strlen(dir), nr = strlen(rel);
    joined = malloc(nd + nr + 2);
    if (!joined) {
        err = TW_ERR_NOMEM;
        why = "cannot be resolved: out of memory";
        goto fail;
    }
    memcpy(joined, dir, nd);
    joined[nd] = '/';
    memcpy(joined + nd + 1, rel, nr + 1);

    dir_real = realpath(dir, NULL);
    if (!dir_real) {
        err = TW_ERR_IO;
        why = "cannot be resolved: the document's folder cannot be resolved";
        goto fail;
    }
    file_real = realpath(joined, NULL);
    if (!file_real) {
        err = TW_ERR_IO;
        why = errno == ENOENT ? "does not exist" : strerror(errno);
        goto fail;
    }
    if (strcmp(file_real, dir_real) == 0) {
        why = "is the document's folder, not a file";
        goto fail;
    }
    const size_t ndr = strlen(dir_real);
    const bool root = ndr == 1 && dir_real[0] == '/';
    if (!root && (strncmp(file_real, dir_real, ndr) != 0 || file_real[ndr] != '/')) {
        why = "resolves outside the document's folder (through a symbolic link)";
        goto fail;
    }
    struct stat st;
    if (stat(file_real, &st) != 0) {
        err = TW_ERR_IO;
        why = strerror(errno);
        goto fail;
    }
    if (!S_ISREG(st.st_mode)) {
        why = "is not a regular file";
        goto fail;
    }
    free(joined);
    free(dir_real);
    *out = file_real;
    *reason = NULL;
    return TW_OK;

fail:
    free(joined);
    free(dir_real);
    free(file_real);
    *reason = why;
    return err;
}
