/*
 * http.h: the fetcher behind the 3D Tiles provider (tiles3d-provider.c):
 * GETs of http://, https:// and file:// URLs through libcurl, with connect
 * and total timeouts, retries with exponential back-off for what may pass
 * (5xx, 408, 429, timeouts, connection errors; never for 404 or another
 * 4xx), and an on-disk cache of bodies keyed by URL that revalidates with
 * If-None-Match and serves a 304 from disk, evicting the oldest files
 * beyond a byte limit.
 *
 * Threading: tw_http_get() may run on any number of threads at once; each
 * call takes a curl handle from a pool (so connections are kept alive
 * between calls) and gives it back. The only process-wide state is
 * curl_global_init(), done once (pthread_once). Never prints: messages go
 * to the caller's buffer.
 */
#ifndef TW_TILESETS_HTTP_H
#define TW_TILESETS_HTTP_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "tileworld/tilesets.h"

struct tw_http;

/* A fetcher with settings (resolved: no zero defaults left); cache_dir is
 * copied (NULL or "": no cache) and made if missing, with its parents. Fails with
 * TW_ERR_IO and err for a cache folder that cannot be made. */
int tw_http_create(const struct tw_tiles3d_settings *settings, struct tw_http **out, char *err,
                   size_t err_size);

/* Makes every transfer in flight and every back-off end now, and every
 * later call fail at once: for a provider going away while workers still
 * fetch. */
void tw_http_cancel(struct tw_http *h);

/* Frees h (accepts NULL); no call may be in flight. */
void tw_http_destroy(struct tw_http *h);

/* GETs url into *body (malloc'd, the caller frees; *size bytes) and
 * returns TW_OK; at most max_bytes bytes. Otherwise a negative tw_error
 * with one line in err ("HTTP 404", "HTTP 500 after 4 attempts",
 * "Timeout was reached after 4 attempts", ...) and *status the HTTP status
 * (0 for none: a connection error); *missing is set for a 404 or 410 (a
 * file:// that does not exist), which is never retried. */
int tw_http_get(struct tw_http *h, const char *url, uint64_t max_bytes, void **body,
                size_t *size, long *status, bool *missing, char *err, size_t err_size);

/* Counters so far (atomically read; any thread). */
void tw_http_stats(const struct tw_http *h, struct tw_tiles3d_stats *out);

#endif
