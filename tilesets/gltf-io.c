/* glTF import, its input (gltf-private.h): the document's file and its
 * external buffers, read confined to the document's folder and within the
 * byte budgets; the GLB container; images, decoded once per source. */
#include "tiles/tiles-internal.h"

#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tilesets/confined-path.h"
#include "tilesets/gltf-private.h"

/* A decoded image takes 4 bytes a pixel, however small its PNG: the size
 * its header gives is bounded before anything is decoded. */
#define MAX_IMAGE_DECODED_BYTES (64ull << 20)

/* ---- reading files ----------------------------------------------------------- */

/* uri with its %XX escapes decoded as RFC 3986 says ('+' is a plus sign;
 * %00 is kept as is), malloc()ed. */
static char *uri_decode(const char *uri)
{
    const size_t n = strlen(uri);
    char *out = malloc(n + 1);
    if (!out)
        return NULL;
    size_t o = 0;
    for (size_t k = 0; k < n; k++) {
        int hi, lo;
        if (uri[k] == '%' && (hi = tw_gltf_hex_digit(uri[k + 1])) >= 0 &&
            (lo = tw_gltf_hex_digit(uri[k + 2])) >= 0 && (hi | lo)) {
            out[o++] = (char)(hi << 4 | lo);
            k += 2;
        } else {
            out[o++] = uri[k];
        }
    }
    out[o] = '\0';
    return out;
}

/* Whether tinygltf's own URL decoding (HTML-form style: '+' is a space) of
 * raw gives decoded: how the reader recognises which buffer tinygltf asks
 * for. */
static bool tinygltf_decodes_to(const char *raw, const char *decoded)
{
    const size_t n = strlen(raw);
    size_t o = 0;
    for (size_t k = 0; k < n; k++) {
        char c = raw[k];
        if (c == '+') {
            c = ' ';
        } else if (c == '%' && n > k + 2) {
            const int hi = tw_gltf_hex_digit(raw[k + 1]);
            const int lo = tw_gltf_hex_digit(raw[k + 2]);
            c = (char)((hi < 0 ? 0 : hi) << 4 | (lo < 0 ? 0 : lo));
            k += 2;
        }
        if (decoded[o++] != c)
            return false;
    }
    return decoded[o] == '\0';
}

/* The data: URIs that tinygltf decodes itself (its IsDataURI()). */
static bool tinygltf_data_uri(const char *uri)
{
    static const char *const prefixes[] = {
        "data:application/octet-stream;base64,", "data:image/jpeg;base64,",
        "data:image/png;base64,", "data:image/bmp;base64,", "data:image/gif;base64,",
        "data:text/plain;base64,", "data:application/gltf-buffer;base64,", NULL};
    for (const char *const *p = prefixes; *p; p++)
        if (strncmp(uri, *p, strlen(*p)) == 0)
            return true;
    return false;
}

/* Reads the open file fd whole, within what is left of this import's byte
 * budget and of the shared one. On failure why completes "\"rel\" ...". */
int tw_gltf_read_fd(struct tw_gltf_importer *im, int fd, uint8_t **data, size_t *size, char *why,
                    size_t why_size)
{
    const uint64_t own_left = im->settings.max_file_bytes - im->bytes_read;
    const struct tw_gltf_shared *sh = im->shared;
    const uint64_t shared_left =
        sh->bytes_read < sh->max_bytes_read ? sh->max_bytes_read - sh->bytes_read : 0;
    const bool by_shared = !im->own_shared && shared_left < own_left;
    char detail[512];
    const int err = tw_confined_read(fd, by_shared ? shared_left : own_left, data, size, detail,
                                     sizeof(detail));
    if (err == TW_ERR_LIMIT && by_shared)
        snprintf(why, why_size,
                 "is too large: with the files read before it for the same manifest it exceeds "
                 "the limit of %llu bytes",
                 (unsigned long long)sh->max_bytes_read);
    else if (err == TW_ERR_LIMIT && im->bytes_read > 0)
        snprintf(why, why_size,
                 "is too large: with the document it exceeds the limit of %llu bytes",
                 (unsigned long long)im->settings.max_file_bytes);
    else if (err)
        snprintf(why, why_size, "%s", detail);
    if (!err) {
        im->bytes_read += *size;
        im->shared->bytes_read += *size;
    }
    return err;
}

/* Opens rel beneath the document's folder and reads it whole (tw_gltf_read_fd()). */
static int read_beneath(struct tw_gltf_importer *im, const char *rel, uint8_t **data, size_t *size,
                        char *why, size_t why_size)
{
    *data = NULL;
    *size = 0;
    int fd = -1;
    const char *reason = NULL;
    int err = tw_confined_open(im->dir_fd, rel, TW_CONFINED_AUTO, &fd, &reason);
    if (err) {
        snprintf(why, why_size, "%s", reason ? reason : "cannot be opened");
        return err;
    }
    err = tw_gltf_read_fd(im, fd, data, size, why, why_size);
    close(fd);
    return err;
}

/* The shim's reader of external buffers. tinygltf hands over its own
 * URL-decoding of the uri, which read '+' as a space; the raw uri comes from
 * the scan (the first unread buffer uri that decodes to the same text) and
 * is decoded here as RFC 3986 says. Confined to the document's folder and
 * to what is left of the byte budget. */
int tw_gltf_read_external(void *user, const char *uri, uint8_t **data, size_t *size)
{
    struct tw_gltf_importer *im = user;
    *data = NULL;
    *size = 0;
    const char *raw = NULL;
    for (uint32_t k = 0; im->scan && k < im->scan->buffer_uri_count && !raw; k++) {
        const struct tw_gltf_scan_string *u = &im->scan->buffer_uris[k];
        if (u->text && !im->uri_used[k] && strlen(u->text) == u->length &&
            !tinygltf_data_uri(u->text) && tinygltf_decodes_to(u->text, uri)) {
            im->uri_used[k] = 1;
            raw = u->text;
        }
    }
    char shown[256];
    tw_log_escape(raw ? raw : uri, shown, sizeof(shown));
    if (!raw) {
        snprintf(im->io_msg, sizeof(im->io_msg),
                 "buffer file \"%s\": cannot tell which buffer's uri it is (internal)", shown);
        return im->io_error = TW_ERR_FORMAT;
    }
    if (im->dir_fd < 0) {
        snprintf(im->io_msg, sizeof(im->io_msg),
                 "buffer file \"%s\": external files are not allowed here", shown);
        return im->io_error = TW_ERR_INVALID;
    }
    char *rel = uri_decode(raw);
    if (!rel) {
        snprintf(im->io_msg, sizeof(im->io_msg), "buffer file \"%s\": out of memory", shown);
        return im->io_error = TW_ERR_NOMEM;
    }
    char why[512];
    const int err = read_beneath(im, rel, data, size, why, sizeof(why));
    free(rel);
    if (err) {
        snprintf(im->io_msg, sizeof(im->io_msg), "buffer file \"%s\" %s", shown, why);
        return im->io_error = err;
    }
    return TW_OK;
}

/* Finds the JSON text: the whole of a .gltf, or the JSON chunk of a .glb
 * after checking the GLB container (glTF 2.0 §4.4). tinygltf 2.7 reads past
 * the end of a BIN chunk whose length ignores its own 8-byte header, so the
 * chunk layout is checked here, and tinygltf is given exactly the header's
 * length. */
int tw_gltf_find_json(struct tw_gltf_importer *im, const uint8_t *data, size_t *size,
                      const uint8_t **text, size_t *text_len)
{
    *text = data;
    *text_len = *size;
    if (*size < 4 || memcmp(data, "glTF", 4) != 0)
        return TW_OK;
    if (*size < 20)
        return tw_gltf_fail(im, TW_ERR_FORMAT, "GLB: %zu bytes, shorter than a header and a chunk",
                            *size);
    const uint32_t version = tw_gltf_le32(data + 4), length = tw_gltf_le32(data + 8);
    if (version != 2)
        return tw_gltf_fail(im, TW_ERR_FORMAT, "GLB: version %u is not 2", version);
    if (length > *size || length < 20)
        return tw_gltf_fail(im, TW_ERR_FORMAT,
                            "GLB: the header's length %u does not fit the %zu bytes", length,
                            *size);
    const uint64_t json_length = tw_gltf_le32(data + 12);
    if (tw_gltf_le32(data + 16) != 0x4E4F534Au)
        return tw_gltf_fail(im, TW_ERR_FORMAT, "GLB: the first chunk is not JSON");
    if (20 + json_length > length)
        return tw_gltf_fail(im, TW_ERR_FORMAT, "GLB: the JSON chunk (%llu bytes) overruns the file",
                            (unsigned long long)json_length);
    const uint64_t next = 20 + json_length;
    if (next < length) {
        if (length - next < 8)
            return tw_gltf_fail(im, TW_ERR_FORMAT, "GLB: a chunk header is cut short at byte %llu",
                                (unsigned long long)next);
        const uint64_t bin_length = tw_gltf_le32(data + next);
        if (next + 8 + bin_length > length)
            return tw_gltf_fail(im, TW_ERR_FORMAT,
                                "GLB: the chunk at byte %llu (%llu bytes) overruns the file",
                                (unsigned long long)next, (unsigned long long)bin_length);
    }
    *size = length;
    *text = data + 20;
    *text_len = (size_t)json_length;
    return TW_OK;
}

/* ---- images ------------------------------------------------------------------- */

/* Decoded images by source: an open-addressing table of entries. */
struct tw_gltf_image_cache {
    struct tw_gltf_decoded_image **entries;
    uint32_t count, cap;
    uint32_t *slots;                  /* entry indices; UINT32_MAX: empty */
    uint32_t size;                    /* a power of two */
};

void tw_gltf_image_cache_destroy(struct tw_gltf_image_cache *c)
{
    if (!c)
        return;
    for (uint32_t k = 0; k < c->count; k++) {
        free(c->entries[k]->rgba);
        free(c->entries[k]);
    }
    free(c->entries);
    free(c->slots);
    free(c);
}

void tw_gltf_shared_finish(struct tw_gltf_shared *shared)
{
    if (!shared)
        return;
    tw_gltf_image_cache_destroy(shared->images);
    shared->images = NULL;
}

static uint64_t hash_words(const uint64_t *w, int n, uint64_t h)
{
    for (int k = 0; k < n; k++) {
        h ^= w[k];
        h *= 0x100000001b3ull;
        h ^= h >> 29;
    }
    return h;
}

static bool same_source(const struct tw_gltf_decoded_image *a,
                        const struct tw_gltf_decoded_image *b)
{
    if (a->source != b->source || a->hash != b->hash ||
        memcmp(a->key, b->key, sizeof(a->key)) != 0)
        return false;
    return a->source != TW_GLTF_SOURCE_DATA || memcmp(a->bytes, b->bytes, (size_t)a->key[1]) == 0;
}

/* The entry of probe's source in *cache (created on first use), or a new
 * one copied from probe with state 0; NULL when out of memory. */
static struct tw_gltf_decoded_image *image_cache_find(struct tw_gltf_image_cache **cache,
                                                      const struct tw_gltf_decoded_image *probe)
{
    struct tw_gltf_image_cache *c = *cache;
    if (!c && !(c = *cache = calloc(1, sizeof(*c))))
        return NULL;
    if (c->size) {
        for (uint32_t h = (uint32_t)probe->hash & (c->size - 1); c->slots[h] != UINT32_MAX;
             h = (h + 1) & (c->size - 1))
            if (same_source(c->entries[c->slots[h]], probe))
                return c->entries[c->slots[h]];
    }
    if (2 * ((uint64_t)c->count + 1) > c->size) {
        if (c->size > UINT32_MAX / 4)
            return NULL;
        const uint32_t size = c->size ? 2 * c->size : 16;
        uint32_t *slots = malloc(sizeof(*slots) * size);
        if (!slots)
            return NULL;
        for (uint32_t k = 0; k < size; k++)
            slots[k] = UINT32_MAX;
        for (uint32_t e = 0; e < c->count; e++) {
            uint32_t h = (uint32_t)c->entries[e]->hash & (size - 1);
            while (slots[h] != UINT32_MAX)
                h = (h + 1) & (size - 1);
            slots[h] = e;
        }
        free(c->slots);
        c->slots = slots;
        c->size = size;
    }
    if (c->count == c->cap) {
        const uint32_t cap = c->cap ? 2 * c->cap : 8;
        struct tw_gltf_decoded_image **grown = realloc(c->entries, sizeof(*grown) * cap);
        if (!grown)
            return NULL;
        c->entries = grown;
        c->cap = cap;
    }
    struct tw_gltf_decoded_image *e = malloc(sizeof(*e));
    if (!e)
        return NULL;
    *e = *probe;
    e->state = 0;
    e->rgba = NULL;
    uint32_t h = (uint32_t)e->hash & (c->size - 1);
    while (c->slots[h] != UINT32_MAX)
        h = (h + 1) & (c->size - 1);
    c->slots[h] = c->count;
    c->entries[c->count++] = e;
    return e;
}

/* Decodes the PNG at bytes into out, within the limits: its header's size is
 * checked before anything is decoded. false (warned) if it cannot be used. */
static bool decode_png(struct tw_gltf_importer *im, const char *what, const uint8_t *bytes,
                       uint64_t size, struct tw_gltf_decoded_image *out)
{
    static const uint8_t signature[8] = {137, 80, 78, 71, 13, 10, 26, 10};
    if (size < 8 || memcmp(bytes, signature, 8) != 0) {
        tw_gltf_warn_texture(
            im, "%s: is not a PNG image; its materials keep their base colour factor", what);
        return false;
    }
    png_image png;
    memset(&png, 0, sizeof(png));
    png.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_memory(&png, bytes, (size_t)size)) {
        tw_gltf_warn_texture(im,
                             "%s: cannot decode the PNG (%s); its materials keep their base colour "
                             "factor",
                             what, png.message);
        png_image_free(&png);
        return false;
    }
    const uint64_t decoded = 4ull * png.width * png.height;
    struct tw_gltf_shared *sh = im->shared;
    char a[32], b[32], c[32];
    if (decoded == 0 || decoded > MAX_IMAGE_DECODED_BYTES) {
        tw_gltf_warn_texture(im,
                             "%s: a %u x %u PNG would decode to %s, more than the limit of %s per "
                             "image; its materials keep their base colour factor",
                             what, png.width, png.height, tw_gltf_byte_size(decoded, a, sizeof(a)),
                             tw_gltf_byte_size(MAX_IMAGE_DECODED_BYTES, b, sizeof(b)));
        png_image_free(&png);
        return false;
    }
    if (sh->decoded_bytes + decoded > sh->max_decoded_bytes) {
        tw_gltf_warn_texture(im,
                             "%s: a %u x %u PNG would decode to %s, and the images decoded before "
                             "it hold %s: more than the limit of %s %s; its materials keep their "
                             "base colour factor",
                             what, png.width, png.height, tw_gltf_byte_size(decoded, a, sizeof(a)),
                             tw_gltf_byte_size(sh->decoded_bytes, b, sizeof(b)),
                             tw_gltf_byte_size(sh->max_decoded_bytes, c, sizeof(c)),
                             im->own_shared ? "per import" : "per manifest");
        png_image_free(&png);
        return false;
    }
    png.format = PNG_FORMAT_RGBA;
    uint8_t *rgba = malloc((size_t)decoded);
    if (!rgba) {
        tw_gltf_warn_texture(im,
                             "%s: out of memory decoding the PNG; its materials keep their base "
                             "colour factor",
                             what);
        png_image_free(&png);
        return false;
    }
    /* Charged before decoding: a PNG that fails halfway cost its time. */
    sh->decoded_bytes += decoded;
    if (!png_image_finish_read(&png, NULL, rgba, 0, NULL)) {
        tw_gltf_warn_texture(im,
                             "%s: cannot decode the PNG (%s); its materials keep their base colour "
                             "factor",
                             what, png.message);
        png_image_free(&png);
        free(rgba);
        return false;
    }
    png_image_free(&png);
    out->width = png.width;
    out->height = png.height;
    out->rgba = rgba;
    return true;
}

/* The entry of an external image file, opened beneath the document's
 * folder: by its identity, in the shared cache, read and decoded the first
 * time. NULL (warned) if unusable. */
static struct tw_gltf_decoded_image *load_image_file(struct tw_gltf_importer *im, uint32_t index,
                                                     const char *uri)
{
    char what[320], shown[224];
    snprintf(what, sizeof(what), "images[%u] \"%s\"", index,
             tw_log_escape(uri, shown, sizeof(shown)));
    if (im->dir_fd < 0) {
        tw_gltf_warn_texture(im,
                             "%s: external files are not allowed here; its materials keep their "
                             "base colour factor",
                             what);
        return NULL;
    }
    char *rel = uri_decode(uri);
    if (!rel) {
        tw_gltf_warn_texture(
            im,
            "%s cannot be read: out of memory; its materials keep their base colour "
            "factor",
            what);
        return NULL;
    }
    int fd = -1;
    const char *reason = NULL;
    int err = tw_confined_open(im->dir_fd, rel, TW_CONFINED_AUTO, &fd, &reason);
    free(rel);
    struct stat st;
    if (!err && fstat(fd, &st) != 0) {
        reason = "cannot be read";
        err = TW_ERR_IO;
    }
    if (err) {
        if (fd >= 0)
            close(fd);
        tw_gltf_warn_texture(im, "%s %s; its materials keep their base colour factor", what,
                             reason ? reason : "cannot be opened");
        return NULL;
    }
    struct tw_gltf_decoded_image probe = {
        TW_GLTF_SOURCE_FILE, {(uint64_t)st.st_dev, (uint64_t)st.st_ino, 0}, NULL, 0, 0, 0, 0, NULL};
    probe.hash = hash_words(probe.key, 3, TW_GLTF_SOURCE_FILE);
    struct tw_gltf_decoded_image *e = image_cache_find(&im->shared->images, &probe);
    if (!e || e->state) {
        close(fd);
        if (!e)
            tw_gltf_warn_texture(
                im, "%s: out of memory; its materials keep their base colour factor", what);
        return e;
    }
    e->state = -1;
    uint8_t *bytes = NULL;
    size_t size = 0;
    char why[512];
    err = tw_gltf_read_fd(im, fd, &bytes, &size, why, sizeof(why));
    close(fd);
    if (err) {
        tw_gltf_warn_texture(im, "%s %s; its materials keep their base colour factor", what, why);
        return e;
    }
    if (decode_png(im, what, bytes, size, e))
        e->state = 1;
    free(bytes);
    return e;
}

/* Image index, resolved once per import and decoded once per source; NULL
 * (warned once per source) if unusable. */
const struct tw_gltf_decoded_image *tw_gltf_load_image(struct tw_gltf_importer *im, uint32_t index)
{
    if (im->image_of[index])
        return im->image_of[index]->state > 0 ? im->image_of[index] : NULL;
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_image *img = &d->images[index];
    struct tw_gltf_decoded_image *e = NULL;
    char what[320];
    if (img->uri) {
        e = load_image_file(im, index, img->uri);
    } else if (img->buffer_view >= 0 || img->data) {
        struct tw_gltf_decoded_image probe = {0};
        const uint8_t *bytes = NULL;
        uint64_t size = 0;
        if (img->buffer_view >= 0) {
            snprintf(what, sizeof(what), "images[%u] (bufferViews[%d])", index, img->buffer_view);
            if ((uint32_t)img->buffer_view >= d->buffer_view_count) {
                tw_gltf_warn_texture(im,
                                     "%s: not a buffer view (%u); its materials keep their base "
                                     "colour factor",
                                     what, d->buffer_view_count);
                return NULL;
            }
            /* Checked against its buffer by tw_gltf_check_buffer_views(). */
            const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[img->buffer_view];
            bytes = d->buffers[v->buffer].data;
            bytes = bytes ? bytes + v->byte_offset : bytes;
            size = bytes ? v->byte_length : 0;
            probe.source = TW_GLTF_SOURCE_VIEW;
            probe.key[0] = (uint64_t)v->buffer;
            probe.key[1] = v->byte_offset;
            probe.key[2] = v->byte_length;
            probe.hash = hash_words(probe.key, 3, TW_GLTF_SOURCE_VIEW);
        } else {
            snprintf(what, sizeof(what), "images[%u] (a data: URI)", index);
            bytes = img->data;
            size = img->size;
            probe.source = TW_GLTF_SOURCE_DATA;
            probe.bytes = bytes;
            probe.key[0] = tw_hash_bytes(bytes, size);
            probe.key[1] = size;
            probe.hash = hash_words(probe.key, 2, TW_GLTF_SOURCE_DATA);
        }
        e = image_cache_find(&im->images, &probe);
        if (!e) {
            tw_gltf_warn_texture(
                im, "%s: out of memory; its materials keep their base colour factor", what);
        } else if (!e->state) {
            e->state = decode_png(im, what, bytes, size, e) ? 1 : -1;
        }
    } else {
        tw_gltf_warn_texture(
            im, "images[%u]: has no data; its materials keep their base colour factor", index);
    }
    if (!e)
        return NULL;
    im->image_of[index] = e;
    return e->state > 0 ? e : NULL;
}
