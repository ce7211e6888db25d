/* Files kept on disk by key, least recently used first out (file-cache.h). */
#include "tiles/file-cache.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "tileworld/tiles.h"

struct tw_file_cache {
    char *dir;
    char suffix[8];             /* with its dot */
    uint64_t max_bytes;
    pthread_mutex_t lock;       /* one eviction at a time */
    _Atomic uint64_t bytes;     /* the files, as last counted plus writes since */
};

static void entry_path(const struct tw_file_cache *c, uint64_t key, char *out, size_t size)
{
    snprintf(out, size, "%s/%016llx%s", c->dir, (unsigned long long)key, c->suffix);
}

struct entry {
    char name[32];
    uint64_t bytes;
    struct timespec mtime;
};

static int older_first(const void *a, const void *b)
{
    const struct entry *x = a, *y = b;
    if (x->mtime.tv_sec != y->mtime.tv_sec)
        return x->mtime.tv_sec < y->mtime.tv_sec ? -1 : 1;
    if (x->mtime.tv_nsec != y->mtime.tv_nsec)
        return x->mtime.tv_nsec < y->mtime.tv_nsec ? -1 : 1;
    return strcmp(x->name, y->name);
}

/* Counts the files and, with evict, removes the oldest until the rest fit
 * 7/8 of the limit, so that the next scan comes only after an eighth of
 * the cache has been written again, not at every write of a full cache.
 * Returns the bytes that stay. */
static uint64_t scan(struct tw_file_cache *c, bool evict)
{
    DIR *d = opendir(c->dir);
    if (!d)
        return 0;
    struct entry *list = NULL;
    size_t count = 0, cap = 0;
    uint64_t total = 0;
    const size_t suffix = strlen(c->suffix);
    const struct dirent *e;
    while ((e = readdir(d))) {
        const size_t n = strlen(e->d_name);
        if (e->d_name[0] == '.' || n <= suffix || n >= sizeof(list->name) ||
            strcmp(e->d_name + n - suffix, c->suffix) != 0)
            continue;
        struct stat st;
        if (fstatat(dirfd(d), e->d_name, &st, 0) != 0 || !S_ISREG(st.st_mode))
            continue;
        if (count == cap) {
            const size_t ncap = cap ? 2 * cap : 256;
            struct entry *grown = realloc(list, ncap * sizeof(*list));
            if (!grown)
                break;
            list = grown;
            cap = ncap;
        }
        memcpy(list[count].name, e->d_name, n + 1);
        list[count].bytes = (uint64_t)st.st_size;
        list[count].mtime = st.st_mtim;
        total += (uint64_t)st.st_size;
        count++;
    }
    const uint64_t keep = c->max_bytes - c->max_bytes / 8;
    if (evict && total > c->max_bytes) {
        qsort(list, count, sizeof(*list), older_first);
        for (size_t k = 0; k < count && total > keep; k++)
            if (unlinkat(dirfd(d), list[k].name, 0) == 0)
                total -= list[k].bytes;
    }
    closedir(d);
    free(list);
    return total;
}

int tw_file_cache_open(const char *dir, const char *suffix, uint64_t max_bytes,
                       struct tw_file_cache **out, char *err, size_t err_size)
{
    *out = NULL;
    if (!dir || !dir[0] || !suffix || strlen(suffix) + 2 > sizeof(((struct tw_file_cache *)0)->suffix) ||
        max_bytes == 0) {
        snprintf(err, err_size, "%s", tw_error_to_str(TW_ERR_INVALID));
        return TW_ERR_INVALID;
    }
    struct tw_file_cache *c = calloc(1, sizeof(*c));
    if (!c || !(c->dir = strdup(dir))) {
        free(c);
        snprintf(err, err_size, "%s", tw_error_to_str(TW_ERR_NOMEM));
        return TW_ERR_NOMEM;
    }
    snprintf(c->suffix, sizeof(c->suffix), ".%s", suffix);
    c->max_bytes = max_bytes;
    pthread_mutex_init(&c->lock, NULL);
    /* The folder and those above it that are missing. */
    for (char *q = c->dir + 1;; q++) {
        if (*q != '/' && *q != '\0')
            continue;
        const char end = *q;
        *q = '\0';
        const bool made = mkdir(c->dir, 0777) == 0 || errno == EEXIST;
        if (!made)
            snprintf(err, err_size, "the cache folder %s cannot be made: %s", c->dir,
                     strerror(errno));
        *q = end;
        if (!made) {
            tw_file_cache_close(c);
            return TW_ERR_IO;
        }
        if (end == '\0')
            break;
    }
    struct stat st;
    if (stat(c->dir, &st) != 0 || !S_ISDIR(st.st_mode)) {
        snprintf(err, err_size, "the cache folder %s is not a folder", c->dir);
        tw_file_cache_close(c);
        return TW_ERR_IO;
    }
    atomic_store(&c->bytes, scan(c, true));
    *out = c;
    return TW_OK;
}

void tw_file_cache_close(struct tw_file_cache *c)
{
    if (!c)
        return;
    pthread_mutex_destroy(&c->lock);
    free(c->dir);
    free(c);
}

FILE *tw_file_cache_get(const struct tw_file_cache *c, uint64_t key)
{
    char path[4200];
    entry_path(c, key, path, sizeof(path));
    return fopen(path, "rb");
}

void tw_file_cache_touch(const struct tw_file_cache *c, uint64_t key)
{
    char path[4200];
    entry_path(c, key, path, sizeof(path));
    utimensat(AT_FDCWD, path, NULL, 0);
}

bool tw_file_cache_put(struct tw_file_cache *c, uint64_t key, const void *head, size_t head_size,
                       const void *body, size_t body_size)
{
    char path[4200], tmp[4200];
    entry_path(c, key, path, sizeof(path));
    snprintf(tmp, sizeof(tmp), "%s/.tmp.XXXXXX", c->dir);
    const int fd = mkstemp(tmp);
    if (fd < 0)
        return false;
    FILE *f = fdopen(fd, "wb");
    if (!f) {
        close(fd);
        unlink(tmp);
        return false;
    }
    bool ok = fwrite(head, 1, head_size, f) == head_size &&
              (body_size == 0 || fwrite(body, 1, body_size, f) == body_size);
    ok = fclose(f) == 0 && ok;
    if (!ok || rename(tmp, path) != 0) {
        unlink(tmp);
        return false;
    }
    /* A file replaced stays counted too: the count errs high, and the
     * scan it brings on counts again. */
    const uint64_t written = (uint64_t)head_size + body_size;
    const uint64_t total = atomic_fetch_add(&c->bytes, written) + written;
    if (total > c->max_bytes) {
        pthread_mutex_lock(&c->lock);
        if (atomic_load(&c->bytes) > c->max_bytes)
            atomic_store(&c->bytes, scan(c, true));
        pthread_mutex_unlock(&c->lock);
    }
    return true;
}
