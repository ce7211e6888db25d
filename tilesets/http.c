/* The fetcher of the 3D Tiles provider (http.h): libcurl easy handles
 * from a pool, retries with back-off, and an ETag cache on disk. */
#include "tilesets/http.h"
#include "tilesets/tilesets-private.h"

#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "tiles/file-cache.h"
#include "tiles/tiles-internal.h"

#ifdef TW_HAVE_CURL
#include <curl/curl.h>

/* Handles kept for reuse (their connections stay open between tiles). */
#define POOL_MAX 64
/* The first line of a cache file; then the URL, the ETag and the body. */
static const char cache_magic[] = "tileworld-http-cache 1\n";

struct tw_http {
    struct tw_tiles3d_settings settings;
    struct tw_file_cache *cache;    /* NULL: no cache */
    pthread_mutex_t lock;           /* guards pool, pool_count, and the back-off waits */
    pthread_cond_t wake;            /* signalled by tw_http_cancel() */
    CURL *pool[POOL_MAX];
    int pool_count;
    _Atomic bool cancelled;
    _Atomic uint64_t requests, bytes, cache_hits, not_modified, retries, failures, stale;
};

static pthread_once_t global_once = PTHREAD_ONCE_INIT;
static CURLcode global_rc = CURLE_FAILED_INIT;

static void global_init(void)
{
    global_rc = curl_global_init(CURL_GLOBAL_DEFAULT);
}

/* ---- the cache ---------------------------------------------------------------- */

static uint64_t cache_key(const char *url)
{
    return tw_hash_bytes((const uint8_t *)url, strlen(url));
}

/* The cached body of url and its ETag, if the cache holds them. */
static bool cache_read(const struct tw_http *h, const char *url, char *etag, size_t etag_size,
                       void **body, size_t *size)
{
    FILE *f = tw_file_cache_get(h->cache, cache_key(url));
    if (!f)
        return false;
    bool ok = false;
    char *line = NULL, *data = NULL;
    size_t line_cap = 0;
    struct stat st;
    if (fstat(fileno(f), &st) != 0)
        goto out;
    ssize_t n = getline(&line, &line_cap, f);
    if (n < 0 || strcmp(line, cache_magic) != 0)
        goto out;
    n = getline(&line, &line_cap, f);
    if (n <= 0 || line[n - 1] != '\n')
        goto out;
    line[n - 1] = '\0';
    if (strcmp(line, url) != 0)     /* another URL of the same hash */
        goto out;
    n = getline(&line, &line_cap, f);
    if (n <= 1 || line[n - 1] != '\n' || (size_t)n > etag_size)
        goto out;
    line[n - 1] = '\0';
    memcpy(etag, line, (size_t)n);
    const long at = ftell(f);
    if (at < 0 || (uint64_t)st.st_size < (uint64_t)at)
        goto out;
    const size_t bytes = (size_t)((uint64_t)st.st_size - (uint64_t)at);
    if (body) {
        data = malloc(bytes ? bytes : 1);
        if (!data || fread(data, 1, bytes, f) != bytes)
            goto out;
        *body = data;
        *size = bytes;
        data = NULL;
    }
    ok = true;
out:
    free(line);
    free(data);
    fclose(f);
    return ok;
}

/* Marks the cached file of url used now (eviction takes the oldest). */
static void cache_touch(const struct tw_http *h, const char *url)
{
    tw_file_cache_touch(h->cache, cache_key(url));
}

/* Stores body under url with etag: written whole or not at all; a failure
 * only loses the copy. */
static void cache_write(struct tw_http *h, const char *url, const char *etag, const void *body,
                        size_t size)
{
    if (!etag[0] || strchr(url, '\n') || strchr(etag, '\n'))
        return;
    const size_t head_size = strlen(cache_magic) + strlen(url) + strlen(etag) + 3;
    char *head = malloc(head_size);
    if (!head)
        return;
    const int n = snprintf(head, head_size, "%s%s\n%s\n", cache_magic, url, etag);
    if (n > 0 && (size_t)n < head_size)
        (void)tw_file_cache_put(h->cache, cache_key(url), head, (size_t)n, body, size);
    free(head);
}

/* ---- creation ------------------------------------------------------------------ */

int tw_http_create(const struct tw_tiles3d_settings *settings, struct tw_http **out, char *err,
                   size_t err_size)
{
    *out = NULL;
    pthread_once(&global_once, global_init);
    if (global_rc != CURLE_OK) {
        snprintf(err, err_size, "libcurl cannot start: %s", curl_easy_strerror(global_rc));
        return TW_ERR_IO;
    }
    struct tw_http *h = calloc(1, sizeof(*h));
    if (!h) {
        snprintf(err, err_size, "%s", tw_error_to_str(TW_ERR_NOMEM));
        return TW_ERR_NOMEM;
    }
    h->settings = *settings;
    pthread_mutex_init(&h->lock, NULL);
    pthread_cond_init(&h->wake, NULL);
    if (settings->cache_dir && settings->cache_dir[0]) {
        const int rc = tw_file_cache_open(settings->cache_dir, "twc", settings->cache_max_bytes,
                                          &h->cache, err, err_size);
        if (rc) {
            tw_http_destroy(h);
            return rc;
        }
    }
    *out = h;
    return TW_OK;
}

void tw_http_cancel(struct tw_http *h)
{
    pthread_mutex_lock(&h->lock);
    atomic_store(&h->cancelled, true);
    pthread_cond_broadcast(&h->wake);
    pthread_mutex_unlock(&h->lock);
}

void tw_http_destroy(struct tw_http *h)
{
    if (!h)
        return;
    for (int k = 0; k < h->pool_count; k++)
        curl_easy_cleanup(h->pool[k]);
    pthread_mutex_destroy(&h->lock);
    pthread_cond_destroy(&h->wake);
    tw_file_cache_close(h->cache);
    free(h);
}

void tw_http_stats(const struct tw_http *h, struct tw_tiles3d_stats *out)
{
    out->requests = atomic_load(&h->requests);
    out->bytes = atomic_load(&h->bytes);
    out->cache_hits = atomic_load(&h->cache_hits);
    out->not_modified = atomic_load(&h->not_modified);
    out->retries = atomic_load(&h->retries);
    out->failures = atomic_load(&h->failures);
    out->stale = atomic_load(&h->stale);
}

/* ---- one request ----------------------------------------------------------------- */

struct transfer {
    struct tw_http *h;
    char *data;
    size_t size, cap;
    uint64_t max_bytes;
    bool too_big;
    char etag[256];
};

static size_t on_body(char *ptr, size_t size, size_t nmemb, void *user)
{
    struct transfer *t = user;
    const size_t n = size * nmemb;
    if ((uint64_t)t->size + n > t->max_bytes) {
        t->too_big = true;
        return 0;
    }
    if (t->size + n > t->cap) {
        size_t cap = t->cap ? t->cap : 65536;
        while (cap < t->size + n)
            cap *= 2;
        char *grown = realloc(t->data, cap);
        if (!grown)
            return 0;
        t->data = grown;
        t->cap = cap;
    }
    memcpy(t->data + t->size, ptr, n);
    t->size += n;
    return n;
}

static size_t on_header(char *ptr, size_t size, size_t nmemb, void *user)
{
    struct transfer *t = user;
    const size_t n = size * nmemb;
    if (n >= 5 && strncmp(ptr, "HTTP/", 5) == 0) {
        t->etag[0] = '\0';      /* a new response (after a redirect) */
    } else if (n > 5 && strncasecmp(ptr, "ETag:", 5) == 0) {
        size_t a = 5, b = n;
        while (a < b && (ptr[a] == ' ' || ptr[a] == '\t'))
            a++;
        while (b > a && (ptr[b - 1] == '\r' || ptr[b - 1] == '\n' || ptr[b - 1] == ' '))
            b--;
        if (b - a < sizeof(t->etag)) {
            memcpy(t->etag, ptr + a, b - a);
            t->etag[b - a] = '\0';
        }
    }
    return n;
}

static int on_progress(void *user, curl_off_t dltotal, curl_off_t dlnow, curl_off_t ultotal,
                       curl_off_t ulnow)
{
    const struct transfer *t = user;
    return atomic_load(&t->h->cancelled) ? 1 : 0;
}

static CURL *take_handle(struct tw_http *h)
{
    pthread_mutex_lock(&h->lock);
    CURL *c = h->pool_count > 0 ? h->pool[--h->pool_count] : NULL;
    pthread_mutex_unlock(&h->lock);
    return c ? c : curl_easy_init();
}

static void give_handle(struct tw_http *h, CURL *c)
{
    curl_easy_reset(c);     /* keeps its open connections */
    pthread_mutex_lock(&h->lock);
    if (h->pool_count < POOL_MAX) {
        h->pool[h->pool_count++] = c;
        c = NULL;
    }
    pthread_mutex_unlock(&h->lock);
    if (c)
        curl_easy_cleanup(c);
}

/* Waits ms unless cancelled; false when cancelled. */
static bool back_off(struct tw_http *h, uint64_t ms)
{
    struct timespec until;
    clock_gettime(CLOCK_REALTIME, &until);
    until.tv_sec += (time_t)(ms / 1000);
    until.tv_nsec += (long)(ms % 1000) * 1000000L;
    if (until.tv_nsec >= 1000000000L) {
        until.tv_sec++;
        until.tv_nsec -= 1000000000L;
    }
    pthread_mutex_lock(&h->lock);
    while (!atomic_load(&h->cancelled))
        if (pthread_cond_timedwait(&h->wake, &h->lock, &until) != 0)
            break;
    pthread_mutex_unlock(&h->lock);
    return !atomic_load(&h->cancelled);
}

static bool may_pass(CURLcode rc, long status)
{
    if (rc == CURLE_OK)
        return status >= 500 || status == 408 || status == 429;
    switch (rc) {
    case CURLE_COULDNT_CONNECT:
    case CURLE_COULDNT_RESOLVE_HOST:
    case CURLE_OPERATION_TIMEDOUT:
    case CURLE_GOT_NOTHING:
    case CURLE_RECV_ERROR:
    case CURLE_SEND_ERROR:
    case CURLE_PARTIAL_FILE:
    case CURLE_SSL_CONNECT_ERROR:
    case CURLE_HTTP2:
    case CURLE_HTTP2_STREAM:
        return true;
    default:
        return false;
    }
}

int tw_http_get(struct tw_http *h, const char *url, uint64_t max_bytes, void **body,
                size_t *size, long *status, bool *missing, char *err, size_t err_size)
{
    *body = NULL;
    *size = 0;
    *status = 0;
    *missing = false;
    const bool use_cache = h->cache && strncmp(url, "file:", 5) != 0;
    char cached_etag[256] = "";
    if (use_cache && !cache_read(h, url, cached_etag, sizeof(cached_etag), NULL, NULL))
        cached_etag[0] = '\0';
    const uint32_t attempts = h->settings.retries == TW_TILES3D_NO_RETRY
                                  ? 1u
                                  : h->settings.retries + 1u;
    int rc = TW_ERR_IO;
    uint64_t delay = h->settings.retry_delay_ms;
    for (uint32_t attempt = 1;; attempt++) {
        if (atomic_load(&h->cancelled)) {
            snprintf(err, err_size, "cancelled (the provider is going away)");
            rc = TW_ERR_STATE;
            break;
        }
        CURL *c = take_handle(h);
        if (!c) {
            snprintf(err, err_size, "libcurl cannot make a handle");
            rc = TW_ERR_NOMEM;
            break;
        }
        struct transfer t = {.h = h, .max_bytes = max_bytes};
        struct curl_slist *headers = NULL;
        char header[300];
        if (cached_etag[0]) {
            snprintf(header, sizeof(header), "If-None-Match: %s", cached_etag);
            headers = curl_slist_append(NULL, header);
        }
        curl_easy_setopt(c, CURLOPT_URL, url);
        curl_easy_setopt(c, CURLOPT_NOSIGNAL, 1L);
        curl_easy_setopt(c, CURLOPT_PROTOCOLS_STR, "http,https,file");
        curl_easy_setopt(c, CURLOPT_REDIR_PROTOCOLS_STR, "http,https");
        curl_easy_setopt(c, CURLOPT_FOLLOWLOCATION, 1L);
        curl_easy_setopt(c, CURLOPT_MAXREDIRS, 5L);
        curl_easy_setopt(c, CURLOPT_CONNECTTIMEOUT_MS, (long)h->settings.connect_timeout_ms);
        curl_easy_setopt(c, CURLOPT_TIMEOUT_MS, (long)h->settings.timeout_ms);
        curl_easy_setopt(c, CURLOPT_WRITEFUNCTION, on_body);
        curl_easy_setopt(c, CURLOPT_WRITEDATA, &t);
        curl_easy_setopt(c, CURLOPT_HEADERFUNCTION, on_header);
        curl_easy_setopt(c, CURLOPT_HEADERDATA, &t);
        curl_easy_setopt(c, CURLOPT_XFERINFOFUNCTION, on_progress);
        curl_easy_setopt(c, CURLOPT_XFERINFODATA, &t);
        curl_easy_setopt(c, CURLOPT_NOPROGRESS, 0L);
        curl_easy_setopt(c, CURLOPT_USERAGENT, "tileworld");
        if (headers)
            curl_easy_setopt(c, CURLOPT_HTTPHEADER, headers);
        atomic_fetch_add(&h->requests, 1);
        const CURLcode cr = curl_easy_perform(c);
        long code = 0;
        curl_easy_getinfo(c, CURLINFO_RESPONSE_CODE, &code);
        give_handle(h, c);
        curl_slist_free_all(headers);
        atomic_fetch_add(&h->bytes, t.size);
        *status = code;
        if (cr == CURLE_OK && (code == 0 || (code >= 200 && code < 300))) {
            if (use_cache)
                cache_write(h, url, t.etag, t.data, t.size);
            *body = t.data ? t.data : malloc(1);
            *size = t.size;
            return *body ? TW_OK : TW_ERR_NOMEM;
        }
        if (cr == CURLE_OK && code == 304 && cached_etag[0]) {
            atomic_fetch_add(&h->not_modified, 1);
            free(t.data);
            char etag[256];
            if (cache_read(h, url, etag, sizeof(etag), body, size)) {
                cache_touch(h, url);
                atomic_fetch_add(&h->cache_hits, 1);
                return TW_OK;
            }
            /* The copy went meanwhile (evicted): ask again, unconditionally. */
            cached_etag[0] = '\0';
            attempt--;
            continue;
        }
        free(t.data);
        if (t.too_big) {
            snprintf(err, err_size, "more than %llu bytes (the glTF limit, max_file_bytes)",
                     (unsigned long long)max_bytes);
            rc = TW_ERR_LIMIT;
            break;
        }
        *missing = (cr == CURLE_OK && (code == 404 || code == 410)) ||
                   cr == CURLE_FILE_COULDNT_READ_FILE || cr == CURLE_REMOTE_FILE_NOT_FOUND;
        const bool retry = may_pass(cr, code) && !atomic_load(&h->cancelled);
        if (cr == CURLE_OK)
            snprintf(err, err_size, "HTTP %ld", code);
        else
            snprintf(err, err_size, "%s", curl_easy_strerror(cr));
        if (!retry || attempt >= attempts) {
            /* The server cannot answer now (a 5xx, a timeout, a lost
             * connection, retries spent): a copy in the cache is better than
             * a hole (HTTP's stale-if-error). Not for a 404 or another 4xx:
             * the server said what it has. */
            char etag[256];
            if (use_cache && may_pass(cr, code) && !atomic_load(&h->cancelled) &&
                cache_read(h, url, etag, sizeof(etag), body, size)) {
                cache_touch(h, url);
                atomic_fetch_add(&h->stale, 1);
                return TW_OK;
            }
            if (attempt > 1) {
                const size_t n = strlen(err);
                snprintf(err + n, err_size - n, " after %u attempts", attempt);
            }
            rc = TW_ERR_IO;
            break;
        }
        atomic_fetch_add(&h->retries, 1);
        if (!back_off(h, delay))
            continue;   /* cancelled: the loop's first check ends it */
        delay *= 2;
    }
    atomic_fetch_add(&h->failures, 1);
    return rc;
}

#else /* no libcurl */

struct tw_http {
    int unused;
};

int tw_http_create(const struct tw_tiles3d_settings *settings, struct tw_http **out, char *err,
                   size_t err_size)
{
    *out = NULL;
    snprintf(err, err_size, "this build has no libcurl (install libcurl4-openssl-dev and "
             "configure again): it cannot fetch 3D Tiles");
    return TW_ERR_INVALID;
}

void tw_http_cancel(struct tw_http *h)
{
}

void tw_http_destroy(struct tw_http *h)
{
    free(h);
}

int tw_http_get(struct tw_http *h, const char *url, uint64_t max_bytes, void **body,
                size_t *size, long *status, bool *missing, char *err, size_t err_size)
{
    snprintf(err, err_size, "this build has no libcurl");
    return TW_ERR_INVALID;
}

void tw_http_stats(const struct tw_http *h, struct tw_tiles3d_stats *out)
{
    memset(out, 0, sizeof(*out));
}

#endif
