/* glTF import (tilesets.h): tinygltf parses (gltf-shim.cpp), this file
 * checks everything itself and converts.
 *
 * tinygltf accepts documents with dangling references, out-of-range indices,
 * overlong buffer views and node loops, so nothing it returns is trusted:
 * every index is range-checked before use, every byte range is checked
 * against its buffer view and buffer with overflow-safe arithmetic, every
 * index value against its vertex count, every float for finiteness, and the
 * node graph for cycles and shared children before it is walked (iteratively:
 * a deep hierarchy cannot exhaust the stack). Allocation sizes are bounded by
 * the settings' limits, checked before anything is allocated. The first
 * problem found ends the import with one message naming the file, the
 * element and the reason. */
#include "tiles/tiles-internal.h"
#include "tileworld/tilesets.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <png.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tilesets/confined-path.h"
#include "tilesets/gltf-scan.h"
#include "tilesets/gltf-shim.h"
#include "tilesets/tilesets-private.h"

#define DEFAULT_MAX_FILE_BYTES (256ull << 20)
#define DEFAULT_MAX_TRIANGLES 10000000ull
/* JSON nesting deeper than this is refused before tinygltf sees it: its
 * value parser recurses once per level. */
#define MAX_JSON_DEPTH 256
/* tinygltf holds the whole JSON tree, at tens to hundreds of bytes per
 * value: bound the count so that a file within max_file_bytes cannot make it
 * allocate gigabytes. Real documents keep their bulk in buffers. */
#define MAX_JSON_VALUES (4 << 20)
/* Memory is bounded by the size of the document: what tinygltf, the shim and
 * this file will hold for the document's JSON (estimated from the scan,
 * before anything is parsed) may not exceed MEMORY_BASE + MEMORY_PER_BYTE
 * bytes per byte of JSON text, nor MEMORY_MAX. Real documents need a few
 * bytes per byte (their bulk is binary); a file of empty objects would need
 * hundreds. Buffers and images are bounded by max_file_bytes on their own. */
#define MEMORY_BASE (64ull << 20)
#define MEMORY_PER_BYTE 32ull
#define MEMORY_MAX (2ull << 30)

enum {
    COMP_BYTE = 5120,
    COMP_UNSIGNED_BYTE = 5121,
    COMP_SHORT = 5122,
    COMP_UNSIGNED_SHORT = 5123,
    COMP_UNSIGNED_INT = 5125,
    COMP_FLOAT = 5126,
};

/* tinygltf's TINYGLTF_TYPE_* codes. */
enum {
    TYPE_VEC2 = 2,
    TYPE_VEC3 = 3,
    TYPE_VEC4 = 4,
    TYPE_MAT2 = 32 + 2,
    TYPE_MAT3 = 32 + 3,
    TYPE_MAT4 = 32 + 4,
    TYPE_SCALAR = 64 + 1,
};

enum {
    MODE_POINTS = 0,
    MODE_LINES = 1,
    MODE_LINE_LOOP = 2,
    MODE_LINE_STRIP = 3,
    MODE_TRIANGLES = 4,
    MODE_TRIANGLE_STRIP = 5,
    MODE_TRIANGLE_FAN = 6,
};

static const float default_grey[4] = {0.6f, 0.6f, 0.6f, 1.0f};

void tw_gltf_default_settings(struct tw_gltf_settings *s)
{
    s->max_file_bytes = DEFAULT_MAX_FILE_BYTES;
    s->max_triangles = DEFAULT_MAX_TRIANGLES;
}

static struct tw_gltf_settings resolve_settings(const struct tw_gltf_settings *given)
{
    struct tw_gltf_settings s;
    tw_gltf_default_settings(&s);
    if (given && given->max_file_bytes)
        s.max_file_bytes = given->max_file_bytes;
    if (given && given->max_triangles)
        s.max_triangles = given->max_triangles;
    /* Keeps 3 * max_triangles and byte sizes far from overflow. */
    if (s.max_triangles > (1ull << 40))
        s.max_triangles = 1ull << 40;
    return s;
}

/* ---- the import context and its one error message ------------------------------ */

struct importer {
    const char *name;                 /* for messages */
    char shown[256];                  /* name, escaped (tiles.h tw_log_escape()) */
    int dir_fd;                       /* folder of external files; -1: none allowed */
    struct tw_gltf_settings settings;
    uint64_t bytes_read;              /* the file and its external buffers */
    const struct tw_gltf_doc *doc;
    const struct tw_gltf_scan *scan;  /* the JSON's first pass: raw buffer URIs */
    uint8_t *uri_used;                /* per scan buffer URI: handed to tinygltf already */
    char msg[1024];                   /* the first error, "<element>: <reason>" */
    int io_error;                     /* set by the external-file reader */
    char io_msg[800];
    const struct tw_log *log;         /* for warnings */
    struct tw_gltf_shared *shared;    /* bytes read and decoded with other imports */
    bool own_shared;                  /* shared is own */
    struct tw_gltf_shared own;
    struct tw_gltf_image_cache *images; /* images in the document, by source */
    struct decoded_image **image_of;  /* per document image: its entry, once resolved */
    struct material_texture *material_textures; /* per document material */
    uint32_t texture_warnings;        /* shown, then only counted */
    struct accessor_facts *facts;     /* per accessor, what its checks found */
    uint64_t checked_bytes;           /* of accessor data read by the checks */
    uint32_t skipped_primitives;      /* points and lines, not drawn */
    char skipped_first[160];          /* the first of them, for the warning */
};

static int fail(struct importer *im, int err, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

static int fail(struct importer *im, int err, const char *fmt, ...)
{
    if (!im->msg[0]) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(im->msg, sizeof(im->msg), fmt, ap);
        va_end(ap);
    }
    return err;
}

static void warn(struct importer *im, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static void warn(struct importer *im, const char *fmt, ...)
{
    char text[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof(text), fmt, ap);
    va_end(ap);
    tw_log_printf(im->log, TW_LOG_WARN, "%s: %s", im->shown, text);
}

/* "4.3 GiB", "17 MiB", "300 KiB", "12 bytes". */
static const char *byte_size(uint64_t n, char *out, size_t size)
{
    if (n >= (1ull << 30))
        snprintf(out, size, "%.1f GiB", (double)n / (double)(1ull << 30));
    else if (n >= (1ull << 20))
        snprintf(out, size, "%llu MiB", (unsigned long long)((n + (1ull << 19)) >> 20));
    else if (n >= 1024)
        snprintf(out, size, "%llu KiB", (unsigned long long)((n + 512) >> 10));
    else
        snprintf(out, size, "%llu bytes", (unsigned long long)n);
    return out;
}

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
static int read_fd(struct importer *im, int fd, uint8_t **data, size_t *size, char *why,
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

/* Opens rel beneath the document's folder and reads it whole (read_fd()). */
static int read_beneath(struct importer *im, const char *rel, uint8_t **data, size_t *size,
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
    err = read_fd(im, fd, data, size, why, why_size);
    close(fd);
    return err;
}

/* The shim's reader of external buffers. tinygltf hands over its own
 * URL-decoding of the uri, which read '+' as a space; the raw uri comes from
 * the scan (the first unread buffer uri that decodes to the same text) and
 * is decoded here as RFC 3986 says. Confined to the document's folder and
 * to what is left of the byte budget. */
static int read_external(void *user, const char *uri, uint8_t **data, size_t *size)
{
    struct importer *im = user;
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

static uint32_t le32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* Finds the JSON text: the whole of a .gltf, or the JSON chunk of a .glb
 * after checking the GLB container (glTF 2.0 §4.4). tinygltf 2.7 reads past
 * the end of a BIN chunk whose length ignores its own 8-byte header, so the
 * chunk layout is checked here, and tinygltf is given exactly the header's
 * length. */
static int find_json(struct importer *im, const uint8_t *data, size_t *size,
                     const uint8_t **text, size_t *text_len)
{
    *text = data;
    *text_len = *size;
    if (*size < 4 || memcmp(data, "glTF", 4) != 0)
        return TW_OK;
    if (*size < 20)
        return fail(im, TW_ERR_FORMAT, "GLB: %zu bytes, shorter than a header and a chunk",
                    *size);
    const uint32_t version = le32(data + 4), length = le32(data + 8);
    if (version != 2)
        return fail(im, TW_ERR_FORMAT, "GLB: version %u is not 2", version);
    if (length > *size || length < 20)
        return fail(im, TW_ERR_FORMAT, "GLB: the header's length %u does not fit the %zu bytes",
                    length, *size);
    const uint64_t json_length = le32(data + 12);
    if (le32(data + 16) != 0x4E4F534Au)
        return fail(im, TW_ERR_FORMAT, "GLB: the first chunk is not JSON");
    if (20 + json_length > length)
        return fail(im, TW_ERR_FORMAT, "GLB: the JSON chunk (%llu bytes) overruns the file",
                    (unsigned long long)json_length);
    const uint64_t next = 20 + json_length;
    if (next < length) {
        if (length - next < 8)
            return fail(im, TW_ERR_FORMAT, "GLB: a chunk header is cut short at byte %llu",
                        (unsigned long long)next);
        const uint64_t bin_length = le32(data + next);
        if (next + 8 + bin_length > length)
            return fail(im, TW_ERR_FORMAT,
                        "GLB: the chunk at byte %llu (%llu bytes) overruns the file",
                        (unsigned long long)next, (unsigned long long)bin_length);
    }
    *size = length;
    *text = data + 20;
    *text_len = (size_t)json_length;
    return TW_OK;
}

/* ---- accessors ----------------------------------------------------------------- */

static uint32_t component_size(int32_t comp)
{
    switch (comp) {
    case COMP_BYTE:
    case COMP_UNSIGNED_BYTE:
        return 1;
    case COMP_SHORT:
    case COMP_UNSIGNED_SHORT:
        return 2;
    case COMP_UNSIGNED_INT:
    case COMP_FLOAT:
        return 4;
    default:
        return 0;
    }
}

static uint32_t type_components(int32_t type)
{
    switch (type) {
    case TYPE_SCALAR:
        return 1;
    case TYPE_VEC2:
        return 2;
    case TYPE_VEC3:
        return 3;
    case TYPE_VEC4:
    case TYPE_MAT2:
        return 4;
    case TYPE_MAT3:
        return 9;
    case TYPE_MAT4:
        return 16;
    default:
        return 0;
    }
}

static const char *type_name(int32_t type)
{
    switch (type) {
    case TYPE_SCALAR: return "SCALAR";
    case TYPE_VEC2: return "VEC2";
    case TYPE_VEC3: return "VEC3";
    case TYPE_VEC4: return "VEC4";
    case TYPE_MAT2: return "MAT2";
    case TYPE_MAT3: return "MAT3";
    case TYPE_MAT4: return "MAT4";
    default: return "an unknown type";
    }
}

static const char *component_name(int32_t comp)
{
    switch (comp) {
    case COMP_BYTE: return "BYTE";
    case COMP_UNSIGNED_BYTE: return "UNSIGNED_BYTE";
    case COMP_SHORT: return "SHORT";
    case COMP_UNSIGNED_SHORT: return "UNSIGNED_SHORT";
    case COMP_UNSIGNED_INT: return "UNSIGNED_INT";
    case COMP_FLOAT: return "FLOAT";
    default: return "an unknown component type";
    }
}

/* Bytes of one element; 0 if the type or component type is invalid. Matrix
 * columns are padded to 4 bytes (glTF 2.0 §3.6.2.4). */
static uint64_t element_size(int32_t comp, int32_t type)
{
    const uint64_t cs = component_size(comp), nc = type_components(type);
    if (!cs || !nc)
        return 0;
    if (type == TYPE_MAT2 && cs == 1)
        return 8;
    if (type == TYPE_MAT3 && cs == 1)
        return 12;
    if (type == TYPE_MAT3 && cs == 2)
        return 24;
    return cs * nc;
}

static uint64_t view_stride(const struct tw_gltf_doc_buffer_view *v, uint64_t elem)
{
    return v->byte_stride ? v->byte_stride : elem;
}

/* Checks that [offset, offset + stride * (count - 1) + elem) lies within a
 * view of view_length bytes, without overflow. count >= 1. */
static bool range_fits(uint64_t offset, uint64_t stride, uint64_t count, uint64_t elem,
                       uint64_t view_length)
{
    if (offset > view_length || elem > view_length - offset)
        return false;
    const uint64_t room = view_length - offset - elem;
    return count - 1 == 0 || stride == 0 || (count - 1) <= room / stride;
}

static int check_buffer_views(struct importer *im)
{
    const struct tw_gltf_doc *d = im->doc;
    for (uint32_t k = 0; k < d->buffer_view_count; k++) {
        const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[k];
        if (v->buffer < 0 || (uint32_t)v->buffer >= d->buffer_count)
            return fail(im, TW_ERR_FORMAT, "bufferViews[%u].buffer: %d is not a buffer (%u)", k,
                        v->buffer, d->buffer_count);
        const uint64_t size = d->buffers[v->buffer].size;
        if (v->byte_offset > size || v->byte_length > size - v->byte_offset)
            return fail(im, TW_ERR_FORMAT,
                        "bufferViews[%u]: bytes [%llu, %llu + %llu) overrun buffers[%d] "
                        "(%llu bytes)",
                        k, (unsigned long long)v->byte_offset,
                        (unsigned long long)v->byte_offset, (unsigned long long)v->byte_length,
                        v->buffer, (unsigned long long)size);
    }
    return TW_OK;
}

static uint32_t load_uint(const uint8_t *p, int32_t comp);
static const uint8_t *view_data(const struct tw_gltf_doc *d, int32_t view, int32_t offset);

/* What the data checks learnt of an accessor: each is read once per import
 * however many primitives use it. */
enum {
    FACT_POSITIONS_OK = 1,            /* finite and within bounds */
    FACT_INDICES_READ = 2,            /* index_max and FACT_RESTART known */
    FACT_RESTART = 4,                 /* holds its type's largest value */
};

struct accessor_facts {
    uint8_t flags;
    uint32_t index_max;
};

/* Charges the checks' reading of n more bytes of accessor data to what the
 * input allows: overlapping accessors could otherwise make a buffer be
 * read again for each (CHECK_BASE + CHECK_PER_BYTE bytes per byte of the
 * file and its buffers). */
#define CHECK_BASE (64ull << 20)
#define CHECK_PER_BYTE 4ull

static int charge_check(struct importer *im, int32_t acc, uint64_t n)
{
    const uint64_t allowed = CHECK_BASE + CHECK_PER_BYTE * im->bytes_read;
    im->checked_bytes += n;
    if (im->checked_bytes <= allowed)
        return TW_OK;
    char a[32], b[32];
    return fail(im, TW_ERR_LIMIT,
                "accessors[%d]: the meshes' accessors hold %s to check, more than the %s "
                "allowed for %llu bytes of file and buffers (64 MiB + 4 bytes per byte): "
                "accessors overlap",
                acc, byte_size(im->checked_bytes, a, sizeof(a)), byte_size(allowed, b, sizeof(b)),
                (unsigned long long)im->bytes_read);
}


static int check_accessors(struct importer *im)
{
    const struct tw_gltf_doc *d = im->doc;
    for (uint32_t k = 0; k < d->accessor_count; k++) {
        const struct tw_gltf_doc_accessor *a = &d->accessors[k];
        const uint64_t elem = element_size(a->component_type, a->type);
        if (!component_size(a->component_type))
            return fail(im, TW_ERR_FORMAT, "accessors[%u].componentType: %d is not valid", k,
                        a->component_type);
        if (!elem)
            return fail(im, TW_ERR_FORMAT, "accessors[%u].type is not valid", k);
        if (a->count < 1 || a->count > UINT32_MAX)
            return fail(im, TW_ERR_FORMAT, "accessors[%u].count: %llu is not in [1, 2^32)", k,
                        (unsigned long long)a->count);
        if (a->buffer_view >= 0) {
            if ((uint32_t)a->buffer_view >= d->buffer_view_count)
                return fail(im, TW_ERR_FORMAT,
                            "accessors[%u].bufferView: %d is not a buffer view (%u)", k,
                            a->buffer_view, d->buffer_view_count);
            const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[a->buffer_view];
            const uint64_t stride = view_stride(v, elem);
            if (stride < elem)
                return fail(im, TW_ERR_FORMAT,
                            "accessors[%u]: bufferViews[%d].byteStride %llu is smaller than "
                            "one element (%llu bytes)",
                            k, a->buffer_view, (unsigned long long)stride,
                            (unsigned long long)elem);
            /* glTF 2.0 §3.6.2.4: data aligned to its component size. */
            const uint32_t cs = component_size(a->component_type);
            if (a->byte_offset % cs != 0 || (v->byte_offset + a->byte_offset) % cs != 0)
                return fail(im, TW_ERR_FORMAT,
                            "accessors[%u].byteOffset: %llu puts its data at byte %llu of "
                            "buffers[%d], not a multiple of %u (its component type, %s, is "
                            "aligned to its size)",
                            k, (unsigned long long)a->byte_offset,
                            (unsigned long long)(v->byte_offset + a->byte_offset), v->buffer,
                            cs, component_name(a->component_type));
            if (!range_fits(a->byte_offset, stride, a->count, elem, v->byte_length))
                return fail(im, TW_ERR_FORMAT,
                            "accessors[%u]: %llu elements of %llu bytes every %llu bytes from "
                            "byte %llu overrun bufferViews[%d] (%llu bytes)",
                            k, (unsigned long long)a->count, (unsigned long long)elem,
                            (unsigned long long)stride, (unsigned long long)a->byte_offset,
                            a->buffer_view, (unsigned long long)v->byte_length);
        } else if (a->buffer_view != -1) {
            return fail(im, TW_ERR_FORMAT, "accessors[%u].bufferView: %d is not a buffer view",
                        k, a->buffer_view);
        }
        if (!a->sparse)
            continue;
        if (a->sparse_count < 1 || (uint64_t)a->sparse_count > a->count)
            return fail(im, TW_ERR_FORMAT, "accessors[%u].sparse.count: %d is not in [1, %llu]",
                        k, a->sparse_count, (unsigned long long)a->count);
        const int32_t ic = a->sparse_indices_component_type;
        if (ic != COMP_UNSIGNED_BYTE && ic != COMP_UNSIGNED_SHORT && ic != COMP_UNSIGNED_INT)
            return fail(im, TW_ERR_FORMAT,
                        "accessors[%u].sparse.indices.componentType: %d is not an unsigned "
                        "integer type",
                        k, ic);
        const struct {
            const char *what;
            int32_t view;
            int32_t offset;
            uint64_t elem;
        } parts[2] = {
            {"indices", a->sparse_indices_view, a->sparse_indices_offset, component_size(ic)},
            {"values", a->sparse_values_view, a->sparse_values_offset, elem},
        };
        for (int p = 0; p < 2; p++) {
            if (parts[p].view < 0 || (uint32_t)parts[p].view >= d->buffer_view_count)
                return fail(im, TW_ERR_FORMAT,
                            "accessors[%u].sparse.%s.bufferView: %d is not a buffer view (%u)",
                            k, parts[p].what, parts[p].view, d->buffer_view_count);
            if (parts[p].offset < 0)
                return fail(im, TW_ERR_FORMAT, "accessors[%u].sparse.%s.byteOffset is negative",
                            k, parts[p].what);
            const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[parts[p].view];
            if (!range_fits((uint64_t)parts[p].offset, parts[p].elem, (uint64_t)a->sparse_count,
                            parts[p].elem, v->byte_length))
                return fail(im, TW_ERR_FORMAT,
                            "accessors[%u].sparse.%s: %d elements from byte %d overrun "
                            "bufferViews[%d] (%llu bytes)",
                            k, parts[p].what, a->sparse_count, parts[p].offset, parts[p].view,
                            (unsigned long long)v->byte_length);
            const uint32_t cs = component_size(p == 0 ? ic : a->component_type);
            if ((v->byte_offset + (uint64_t)parts[p].offset) % cs != 0)
                return fail(im, TW_ERR_FORMAT,
                            "accessors[%u].sparse.%s.byteOffset: %d puts its data at byte %llu "
                            "of buffers[%d], not a multiple of %u (its component size)",
                            k, parts[p].what, parts[p].offset,
                            (unsigned long long)(v->byte_offset + (uint64_t)parts[p].offset),
                            v->buffer, cs);
        }
        /* The spec: sparse indices strictly increase (and so stay below
         * count, checked as they are read too). */
        const uint8_t *idx = view_data(d, a->sparse_indices_view, a->sparse_indices_offset);
        const uint64_t is = component_size(ic);
        int err = charge_check(im, (int32_t)k, is * (uint64_t)a->sparse_count);
        if (err)
            return err;
        for (uint32_t e = 0; e < (uint32_t)a->sparse_count; e++) {
            const uint32_t target = load_uint(idx + e * is, ic);
            const uint32_t before = e ? load_uint(idx + (e - 1) * is, ic) : 0;
            if (target >= a->count)
                return fail(im, TW_ERR_FORMAT,
                            "accessors[%u].sparse.indices[%u]: %u is not below the count %llu",
                            k, e, target, (unsigned long long)a->count);
            if (e > 0 && target <= before)
                return fail(im, TW_ERR_FORMAT,
                            "accessors[%u].sparse.indices[%u]: %u follows %u; sparse indices "
                            "must strictly increase",
                            k, e, target, before);
        }
    }
    return TW_OK;
}

static uint32_t load_uint(const uint8_t *p, int32_t comp)
{
    switch (comp) {
    case COMP_UNSIGNED_BYTE:
        return p[0];
    case COMP_UNSIGNED_SHORT:
        return (uint32_t)p[0] | (uint32_t)p[1] << 8;
    default:
        return le32(p);
    }
}

static float load_float(const uint8_t *p)
{
    const uint32_t bits = le32(p);
    float f;
    memcpy(&f, &bits, sizeof(f));
    return f;
}

/* One component as a float: normalized integers map to [0, 1] or [-1, 1]
 * (glTF 2.0 §3.11), other integers keep their value (KHR_mesh_quantization:
 * the node's transform dequantises them). */
static float load_as_float(const uint8_t *p, int32_t comp, bool normalized)
{
    switch (comp) {
    case COMP_FLOAT:
        return load_float(p);
    case COMP_UNSIGNED_BYTE:
        return normalized ? (float)p[0] / 255.0f : (float)p[0];
    case COMP_UNSIGNED_SHORT: {
        const uint32_t v = load_uint(p, comp);
        return normalized ? (float)v / 65535.0f : (float)v;
    }
    case COMP_BYTE: {
        const int v = (int)p[0] - (p[0] > 127 ? 256 : 0);
        return normalized ? fmaxf((float)v / 127.0f, -1.0f) : (float)v;
    }
    case COMP_SHORT: {
        const int32_t u = (int32_t)load_uint(p, COMP_UNSIGNED_SHORT);
        const int32_t v = u - (u > 32767 ? 65536 : 0);
        return normalized ? fmaxf((float)v / 32767.0f, -1.0f) : (float)v;
    }
    case COMP_UNSIGNED_INT:
        return normalized ? (float)((double)le32(p) / 4294967295.0) : (float)le32(p);
    default:
        return 0.0f;
    }
}

/* Start of the accessor's data in its buffer, or NULL when it has no buffer
 * view (zeros). The accessor has been checked. */
static const uint8_t *accessor_base(const struct tw_gltf_doc *d,
                                    const struct tw_gltf_doc_accessor *a, uint64_t *stride)
{
    const uint64_t elem = element_size(a->component_type, a->type);
    *stride = elem;
    if (a->buffer_view < 0)
        return NULL;
    const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[a->buffer_view];
    *stride = view_stride(v, elem);
    return d->buffers[v->buffer].data + v->byte_offset + a->byte_offset;
}

static const uint8_t *view_data(const struct tw_gltf_doc *d, int32_t view, int32_t offset)
{
    const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[view];
    return d->buffers[v->buffer].data + v->byte_offset + (uint64_t)offset;
}

/* Applies sparse substitutions: for each entry, copy(out, target, source). */
static int apply_sparse(struct importer *im, uint32_t index,
                        void (*copy)(void *out, uint32_t target, const uint8_t *src, int32_t comp,
                                     uint32_t n),
                        void *out, uint32_t n)
{
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_accessor *a = &d->accessors[index];
    if (!a->sparse)
        return TW_OK;
    const int32_t ic = a->sparse_indices_component_type;
    const uint64_t is = component_size(ic);
    const uint64_t elem = element_size(a->component_type, a->type);
    const uint8_t *idx = view_data(d, a->sparse_indices_view, a->sparse_indices_offset);
    const uint8_t *val = view_data(d, a->sparse_values_view, a->sparse_values_offset);
    for (uint32_t s = 0; s < (uint32_t)a->sparse_count; s++) {
        const uint32_t target = load_uint(idx + s * is, ic);
        if (target >= a->count)
            return fail(im, TW_ERR_FORMAT,
                        "accessors[%u].sparse.indices[%u]: %u is not below the count %llu",
                        index, s, target, (unsigned long long)a->count);
        copy(out, target, val + s * elem, a->component_type, n);
    }
    return TW_OK;
}

static void copy_unnormalized(void *out, uint32_t target, const uint8_t *src, int32_t comp,
                              uint32_t n)
{
    float *f = (float *)out + (size_t)target * n;
    for (uint32_t c = 0; c < n; c++)
        f[c] = load_as_float(src + component_size(comp) * c, comp, false);
}

static void copy_normalized(void *out, uint32_t target, const uint8_t *src, int32_t comp,
                            uint32_t n)
{
    float *f = (float *)out + (size_t)target * n;
    for (uint32_t c = 0; c < n; c++)
        f[c] = load_as_float(src + component_size(comp) * c, comp, true);
}

static void copy_uint(void *out, uint32_t target, const uint8_t *src, int32_t comp, uint32_t n)
{
    ((uint32_t *)out)[target] = load_uint(src, comp);
}

/* Reads the first n components of a checked accessor as floats (integers
 * normalised if the accessor says so, load_as_float()) into out (count * n). */
static int read_floats(struct importer *im, uint32_t index, uint32_t n, float *out)
{
    const struct tw_gltf_doc_accessor *a = &im->doc->accessors[index];
    uint64_t stride;
    const uint8_t *base = accessor_base(im->doc, a, &stride);
    const uint32_t cs = component_size(a->component_type);
    for (uint64_t k = 0; k < a->count; k++)
        for (uint32_t c = 0; c < n; c++)
            out[k * n + c] = base ? load_as_float(base + k * stride + cs * c, a->component_type,
                                                  a->normalized)
                                  : 0.0f;
    return apply_sparse(im, index, a->normalized ? copy_normalized : copy_unnormalized, out, n);
}

/* Reads a checked unsigned integer SCALAR accessor into out (count). */
static int read_uints(struct importer *im, uint32_t index, uint32_t *out)
{
    const struct tw_gltf_doc_accessor *a = &im->doc->accessors[index];
    uint64_t stride;
    const uint8_t *base = accessor_base(im->doc, a, &stride);
    for (uint64_t k = 0; k < a->count; k++)
        out[k] = base ? load_uint(base + k * stride, a->component_type) : 0;
    return apply_sparse(im, index, copy_uint, out, 1);
}

/* ---- meshes --------------------------------------------------------------------- */

static int32_t find_attribute(const struct tw_gltf_doc_primitive *p, const char *name)
{
    for (uint32_t k = 0; k < p->attribute_count; k++)
        if (p->attributes[k].name && strcmp(p->attributes[k].name, name) == 0)
            return p->attributes[k].accessor;
    return -1;
}

static const char *mode_name(int32_t mode)
{
    switch (mode) {
    case MODE_POINTS: return "POINTS";
    case MODE_LINES: return "LINES";
    case MODE_LINE_LOOP: return "LINE_LOOP";
    case MODE_LINE_STRIP: return "LINE_STRIP";
    default: return "an unknown mode";
    }
}

static bool draws_triangles(const struct tw_gltf_doc_primitive *p)
{
    return p->mode == MODE_TRIANGLES || p->mode == MODE_TRIANGLE_STRIP ||
           p->mode == MODE_TRIANGLE_FAN;
}

static bool is_integer(int32_t comp)
{
    return comp == COMP_BYTE || comp == COMP_UNSIGNED_BYTE || comp == COMP_SHORT ||
           comp == COMP_UNSIGNED_SHORT;
}

/* Vertex attribute types: glTF 2.0 §3.7.2.1 and KHR_mesh_quantization
 * (positions of any 8- or 16-bit integers, normalized or not; normals of
 * normalized BYTE or SHORT). */
static bool position_type_ok(const struct tw_gltf_doc_accessor *a)
{
    return a->type == TYPE_VEC3 &&
           ((a->component_type == COMP_FLOAT && !a->normalized) || is_integer(a->component_type));
}

static bool normal_type_ok(const struct tw_gltf_doc_accessor *a)
{
    return a->type == TYPE_VEC3 &&
           ((a->component_type == COMP_FLOAT && !a->normalized) ||
            ((a->component_type == COMP_BYTE || a->component_type == COMP_SHORT) &&
             a->normalized));
}

static int check_meshes(struct importer *im)
{
    const struct tw_gltf_doc *d = im->doc;
    for (uint32_t m = 0; m < d->mesh_count; m++) {
        const struct tw_gltf_doc_mesh *mesh = &d->meshes[m];
        if (mesh->primitive_count == 0)
            return fail(im, TW_ERR_FORMAT, "meshes[%u]: has no primitives", m);
        for (uint32_t k = 0; k < mesh->primitive_count; k++) {
            const struct tw_gltf_doc_primitive *p = &mesh->primitives[k];
            if (p->mode < MODE_POINTS || p->mode > MODE_TRIANGLE_FAN)
                return fail(im, TW_ERR_FORMAT,
                            "meshes[%u].primitives[%u].mode: %d is not a glTF primitive mode "
                            "(0 to 6)",
                            m, k, p->mode);
            for (uint32_t t = 0; t < p->attribute_count; t++) {
                const int32_t acc = p->attributes[t].accessor;
                if (acc < 0 || (uint32_t)acc >= d->accessor_count) {
                    char shown[64];
                    return fail(im, TW_ERR_FORMAT,
                                "meshes[%u].primitives[%u].attributes.%s: %d is not an "
                                "accessor (%u)",
                                m, k,
                                tw_log_escape(p->attributes[t].name ? p->attributes[t].name : "?",
                                              shown, sizeof(shown)),
                                acc, d->accessor_count);
                }
            }
            if (p->indices < -1 || (p->indices >= 0 && (uint32_t)p->indices >= d->accessor_count))
                return fail(im, TW_ERR_FORMAT,
                            "meshes[%u].primitives[%u].indices: %d is not an accessor (%u)", m,
                            k, p->indices, d->accessor_count);
            if (p->material < -1 ||
                (p->material >= 0 && (uint32_t)p->material >= d->material_count))
                return fail(im, TW_ERR_FORMAT,
                            "meshes[%u].primitives[%u].material: %d is not a material (%u)", m,
                            k, p->material, d->material_count);
            if (!draws_triangles(p)) {
                /* Points and lines are valid glTF that a triangle renderer
                 * does not draw: skipped (one warning per file), never read. */
                if (im->skipped_primitives++ == 0)
                    snprintf(im->skipped_first, sizeof(im->skipped_first),
                             "meshes[%u].primitives[%u].mode: %d (%s)", m, k, p->mode,
                             mode_name(p->mode));
                continue;
            }
            const int32_t pos = find_attribute(p, "POSITION");
            if (pos < 0)
                continue; /* drawn as nothing (glTF 2.0 §3.7.2.1) */
            const struct tw_gltf_doc_accessor *a = &d->accessors[pos];
            if (!position_type_ok(a))
                return fail(im, TW_ERR_FORMAT,
                            "meshes[%u].primitives[%u].attributes.POSITION: accessors[%d] is "
                            "%s of %s%s; positions must be VEC3 of FLOAT, or of BYTE, "
                            "UNSIGNED_BYTE, SHORT or UNSIGNED_SHORT (KHR_mesh_quantization)",
                            m, k, pos, type_name(a->type), a->normalized ? "normalized " : "",
                            component_name(a->component_type));
            const int32_t nrm = find_attribute(p, "NORMAL");
            if (nrm >= 0) {
                const struct tw_gltf_doc_accessor *n = &d->accessors[nrm];
                if (!normal_type_ok(n) || n->count != a->count)
                    return fail(im, TW_ERR_FORMAT,
                                "meshes[%u].primitives[%u].attributes.NORMAL: accessors[%d] "
                                "must be %llu VEC3 like POSITION, of FLOAT or of normalized "
                                "BYTE or SHORT (KHR_mesh_quantization)",
                                m, k, nrm, (unsigned long long)a->count);
            }
            if (p->indices >= 0) {
                const struct tw_gltf_doc_accessor *ix = &d->accessors[p->indices];
                const int32_t c = ix->component_type;
                if (ix->type != TYPE_SCALAR ||
                    (c != COMP_UNSIGNED_BYTE && c != COMP_UNSIGNED_SHORT &&
                     c != COMP_UNSIGNED_INT))
                    return fail(im, TW_ERR_FORMAT,
                                "meshes[%u].primitives[%u].indices: accessors[%d] is %s of "
                                "%s; indices must be SCALAR of UNSIGNED_BYTE, UNSIGNED_SHORT "
                                "or UNSIGNED_INT",
                                m, k, p->indices, type_name(ix->type), component_name(c));
            }
        }
    }
    return TW_OK;
}

/* Triangles of a checked primitive, from its counts alone. */
static int primitive_triangles(struct importer *im, uint32_t m, uint32_t k, uint64_t *tris)
{
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_primitive *p = &d->meshes[m].primitives[k];
    *tris = 0;
    const int32_t pos = find_attribute(p, "POSITION");
    if (pos < 0 || !draws_triangles(p))
        return TW_OK;
    const uint64_t n = p->indices >= 0 ? d->accessors[p->indices].count : d->accessors[pos].count;
    if (p->mode == MODE_TRIANGLES) {
        if (n % 3 != 0)
            return fail(im, TW_ERR_FORMAT,
                        "meshes[%u].primitives[%u]: %llu %s is not a multiple of 3", m, k,
                        (unsigned long long)n, p->indices >= 0 ? "indices" : "vertices");
        *tris = n / 3;
    } else {
        *tris = n >= 3 ? n - 2 : 0;
    }
    return TW_OK;
}

/* The largest value of an index component type, which glTF reserves
 * (primitive restart) and forbids in indices. */
static uint32_t restart_value(int32_t comp)
{
    return comp == COMP_UNSIGNED_BYTE ? 0xffu : comp == COMP_UNSIGNED_SHORT ? 0xffffu
                                                                            : 0xffffffffu;
}

/* Reads the index accessor ia once: its largest value and whether it holds
 * the restart value, sparse substitutes included (and the base values they
 * replace). */
static int read_index_facts(struct importer *im, int32_t ia)
{
    struct accessor_facts *f = &im->facts[ia];
    if (f->flags & FACT_INDICES_READ)
        return TW_OK;
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_accessor *a = &d->accessors[ia];
    const uint64_t size = component_size(a->component_type);
    uint64_t stride;
    const uint8_t *base = accessor_base(d, a, &stride);
    int err = charge_check(im, ia, (base ? a->count * size : 0) +
                                       (a->sparse ? (uint64_t)a->sparse_count * size : 0));
    if (err)
        return err;
    const uint32_t restart = restart_value(a->component_type);
    uint32_t max = 0;
    bool has_restart = false;
    for (uint64_t e = 0; base && e < a->count; e++) {
        const uint32_t i = load_uint(base + e * stride, a->component_type);
        max = i > max ? i : max;
        has_restart |= i == restart;
    }
    if (a->sparse) {
        const uint8_t *val = view_data(d, a->sparse_values_view, a->sparse_values_offset);
        for (int32_t e = 0; e < a->sparse_count; e++) {
            const uint32_t i = load_uint(val + size * (uint64_t)e, a->component_type);
            max = i > max ? i : max;
            has_restart |= i == restart;
        }
    }
    f->index_max = max;
    f->flags |= FACT_INDICES_READ | (has_restart ? FACT_RESTART : 0);
    return TW_OK;
}

/* Checks the data of primitive k of mesh m without allocating: positions
 * finite and within +-TW_TILES_MAX_MESH_COORD, every index below the vertex
 * count and never the restart value (sparse substitutes included; base
 * values that a substitute replaces must be in range too). Runs on every
 * triangle primitive, drawn or not; each accessor is read once. */
static int check_primitive_data(struct importer *im, uint32_t m, uint32_t k)
{
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_primitive *p = &d->meshes[m].primitives[k];
    const int32_t pos = find_attribute(p, "POSITION");
    if (pos < 0 || !draws_triangles(p))
        return TW_OK;
    const struct tw_gltf_doc_accessor *pa = &d->accessors[pos];
    uint64_t stride;
    const uint8_t *base = accessor_base(d, pa, &stride);
    /* Integer positions (KHR_mesh_quantization) are small by their type. */
    const bool floats = pa->component_type == COMP_FLOAT;
    int err;
    if (floats && !(im->facts[pos].flags & FACT_POSITIONS_OK)) {
        if ((err = charge_check(im, pos, (base ? 12 * pa->count : 0) +
                                             (pa->sparse ? 12 * (uint64_t)pa->sparse_count : 0))))
            return err;
        for (uint64_t v = 0; base && v < pa->count; v++) {
            for (int c = 0; c < 3; c++) {
                const float x = load_float(base + v * stride + 4 * c);
                if (!isfinite(x))
                    return fail(im, TW_ERR_FORMAT,
                                "meshes[%u].primitives[%u].attributes.POSITION: accessors[%d] "
                                "element %llu is not finite",
                                m, k, pos, (unsigned long long)v);
                if (fabsf(x) > TW_TILES_MAX_MESH_COORD)
                    return fail(im, TW_ERR_LIMIT,
                                "meshes[%u].primitives[%u].attributes.POSITION: accessors[%d] "
                                "element %llu has %c = %g, beyond +-%g",
                                m, k, pos, (unsigned long long)v, "xyz"[c], x,
                                (double)TW_TILES_MAX_MESH_COORD);
            }
        }
        if (pa->sparse) {
            const uint8_t *val = view_data(d, pa->sparse_values_view, pa->sparse_values_offset);
            for (int32_t e = 0; e < pa->sparse_count; e++) {
                for (int c = 0; c < 3; c++) {
                    const float x = load_float(val + 12 * (uint64_t)e + 4 * c);
                    if (!isfinite(x))
                        return fail(im, TW_ERR_FORMAT,
                                    "meshes[%u].primitives[%u].attributes.POSITION: "
                                    "accessors[%d] sparse value %d is not finite",
                                    m, k, pos, e);
                    if (fabsf(x) > TW_TILES_MAX_MESH_COORD)
                        return fail(im, TW_ERR_LIMIT,
                                    "meshes[%u].primitives[%u].attributes.POSITION: "
                                    "accessors[%d] sparse value %d has %c = %g, beyond +-%g",
                                    m, k, pos, e, "xyz"[c], x, (double)TW_TILES_MAX_MESH_COORD);
                }
            }
        }
        im->facts[pos].flags |= FACT_POSITIONS_OK;
    }
    if (p->indices < 0)
        return TW_OK;
    if ((err = read_index_facts(im, p->indices)))
        return err;
    const struct accessor_facts *f = &im->facts[p->indices];
    const uint64_t nv = pa->count;
    if (f->index_max < nv && !(f->flags & FACT_RESTART))
        return TW_OK;
    /* A bad index: find the first, for the message (once: it ends the
     * import). */
    const struct tw_gltf_doc_accessor *ia = &d->accessors[p->indices];
    const uint32_t restart = restart_value(ia->component_type);
    base = accessor_base(d, ia, &stride);
    for (uint64_t e = 0; base && e < ia->count; e++) {
        const uint32_t i = load_uint(base + e * stride, ia->component_type);
        if (i >= nv)
            return fail(im, TW_ERR_FORMAT,
                        "meshes[%u].primitives[%u].indices: accessors[%d] element %llu is %u, "
                        "not below the vertex count %llu",
                        m, k, p->indices, (unsigned long long)e, i, (unsigned long long)nv);
        if (i == restart)
            return fail(im, TW_ERR_FORMAT,
                        "meshes[%u].primitives[%u].indices: accessors[%d] element %llu is %u, "
                        "the largest %s, which glTF reserves (primitive restart)",
                        m, k, p->indices, (unsigned long long)e, i,
                        component_name(ia->component_type));
    }
    const uint64_t size = component_size(ia->component_type);
    for (int32_t e = 0; ia->sparse && e < ia->sparse_count; e++) {
        const uint8_t *val = view_data(d, ia->sparse_values_view, ia->sparse_values_offset);
        const uint32_t i = load_uint(val + size * (uint64_t)e, ia->component_type);
        if (i >= nv)
            return fail(im, TW_ERR_FORMAT,
                        "meshes[%u].primitives[%u].indices: accessors[%d] sparse value %d is "
                        "%u, not below the vertex count %llu",
                        m, k, p->indices, e, i, (unsigned long long)nv);
        if (i == restart)
            return fail(im, TW_ERR_FORMAT,
                        "meshes[%u].primitives[%u].indices: accessors[%d] sparse value %d is "
                        "%u, the largest %s, which glTF reserves (primitive restart)",
                        m, k, p->indices, e, i, component_name(ia->component_type));
    }
    /* Not reached: read_index_facts() saw one of the values above. */
    return fail(im, TW_ERR_FORMAT,
                "meshes[%u].primitives[%u].indices: accessors[%d] holds an index not below the "
                "vertex count %llu, or the restart value",
                m, k, p->indices, (unsigned long long)nv);
}

static int check_mesh_data(struct importer *im)
{
    int err = TW_OK;
    for (uint32_t m = 0; m < im->doc->mesh_count && !err; m++)
        for (uint32_t k = 0; k < im->doc->meshes[m].primitive_count && !err; k++)
            err = check_primitive_data(im, m, k);
    return err;
}

/* Converts primitive k of mesh m into out (zeroed). A primitive that draws
 * nothing leaves out->triangle_count at 0. */
static int convert_primitive(struct importer *im, uint32_t m, uint32_t k, uint32_t grey,
                             struct tw_gltf_primitive *out)
{
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_primitive *p = &d->meshes[m].primitives[k];
    uint32_t *list = NULL;
    int err;
    uint64_t tris;
    if ((err = primitive_triangles(im, m, k, &tris)) || tris == 0)
        return err;
    const int32_t pos = find_attribute(p, "POSITION");
    const struct tw_gltf_doc_accessor *pa = &d->accessors[pos];
    const uint32_t nv = (uint32_t)pa->count;
    out->vertex_count = nv;
    out->material = p->material >= 0 ? (uint32_t)p->material : grey;
    out->positions = malloc(sizeof(float) * 3 * (size_t)nv);
    out->indices = malloc(sizeof(uint32_t) * 3 * (size_t)tris);
    if (!out->positions || !out->indices)
        return fail(im, TW_ERR_NOMEM, "meshes[%u].primitives[%u]: out of memory", m, k);
    if ((err = read_floats(im, (uint32_t)pos, 3, out->positions)))
        return err;
    out->box = tw_box_empty();
    for (uint32_t v = 0; v < nv; v++) {
        const float *x = out->positions + 3 * (size_t)v;
        if (!isfinite(x[0]) || !isfinite(x[1]) || !isfinite(x[2]))
            return fail(im, TW_ERR_FORMAT,
                        "meshes[%u].primitives[%u].attributes.POSITION: accessors[%d] element "
                        "%u is not finite",
                        m, k, pos, v);
        tw_box_add_point(&out->box, x);
    }

    const int32_t nrm = find_attribute(p, "NORMAL");
    if (nrm >= 0) {
        out->normals = malloc(sizeof(float) * 3 * (size_t)nv);
        if (!out->normals)
            return fail(im, TW_ERR_NOMEM, "meshes[%u].primitives[%u]: out of memory", m, k);
        if ((err = read_floats(im, (uint32_t)nrm, 3, out->normals)))
            return err;
        if (d->accessors[nrm].component_type != COMP_FLOAT) {
            /* Quantised normals are unit length only to within a step. */
            for (uint32_t v = 0; v < nv; v++) {
                float *x = out->normals + 3 * (size_t)v;
                const float len = sqrtf(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
                if (len > 0.0f)
                    for (int c = 0; c < 3; c++)
                        x[c] /= len;
            }
        }
        for (uint64_t c = 0; c < 3ull * nv; c++) {
            if (!isfinite(out->normals[c])) {
                /* Normals are optional: drop them rather than the mesh. */
                free(out->normals);
                out->normals = NULL;
                break;
            }
        }
    }

    /* The primitive's vertex order: its index list, or 0 .. n-1. */
    uint64_t n = nv;
    if (p->indices >= 0) {
        n = d->accessors[p->indices].count;
        list = malloc(sizeof(uint32_t) * (size_t)n);
        if (!list)
            return fail(im, TW_ERR_NOMEM, "meshes[%u].primitives[%u]: out of memory", m, k);
        if ((err = read_uints(im, (uint32_t)p->indices, list)))
            goto out;
        for (uint64_t e = 0; e < n; e++) {
            if (list[e] >= nv) {
                err = fail(im, TW_ERR_FORMAT,
                           "meshes[%u].primitives[%u].indices: accessors[%d] element %llu is "
                           "%u, not below the vertex count %u",
                           m, k, p->indices, (unsigned long long)e, list[e], nv);
                goto out;
            }
        }
    }
#define VERTEX(e) (list ? list[(e)] : (uint32_t)(e))
    uint32_t *ix = out->indices;
    for (uint64_t t = 0; t < tris; t++) {
        switch (p->mode) {
        case MODE_TRIANGLES:
            ix[0] = VERTEX(3 * t);
            ix[1] = VERTEX(3 * t + 1);
            ix[2] = VERTEX(3 * t + 2);
            break;
        case MODE_TRIANGLE_STRIP: /* odd triangles swap to keep the winding */
            ix[0] = VERTEX(t + (t & 1));
            ix[1] = VERTEX(t + 1 - (t & 1));
            ix[2] = VERTEX(t + 2);
            break;
        default: /* MODE_TRIANGLE_FAN */
            ix[0] = VERTEX(t + 1);
            ix[1] = VERTEX(t + 2);
            ix[2] = VERTEX(0);
            break;
        }
        ix += 3;
    }
#undef VERTEX
    out->triangle_count = (uint32_t)tris;
out:
    free(list);
    return err;
}

/* ---- nodes ---------------------------------------------------------------------- */

static bool all_finite(const double *v, uint32_t n)
{
    for (uint32_t k = 0; k < n; k++)
        if (!isfinite(v[k]))
            return false;
    return true;
}

static int check_nodes(struct importer *im, int32_t *parent)
{
    const struct tw_gltf_doc *d = im->doc;
    for (uint32_t k = 0; k < d->node_count; k++)
        parent[k] = -1;
    for (uint32_t k = 0; k < d->node_count; k++) {
        const struct tw_gltf_doc_node *n = &d->nodes[k];
        if (n->mesh < -1 || (n->mesh >= 0 && (uint32_t)n->mesh >= d->mesh_count))
            return fail(im, TW_ERR_FORMAT, "nodes[%u].mesh: %d is not a mesh (%u)", k, n->mesh,
                        d->mesh_count);
        for (uint32_t c = 0; c < n->child_count; c++) {
            const int child = n->children[c];
            if (child < 0 || (uint32_t)child >= d->node_count)
                return fail(im, TW_ERR_FORMAT, "nodes[%u].children[%u]: %d is not a node (%u)",
                            k, c, child, d->node_count);
            if ((uint32_t)child == k)
                return fail(im, TW_ERR_FORMAT,
                            "nodes[%u].children[%u]: the node is its own child (a cycle)", k, c);
            if (parent[child] >= 0)
                return fail(im, TW_ERR_FORMAT,
                            "nodes[%u].children[%u]: nodes[%d] is already a child of nodes[%d]; "
                            "a node has at most one parent",
                            k, c, child, parent[child]);
            parent[child] = (int32_t)k;
        }
        const struct {
            const char *what;
            uint32_t given, want;
            const double *values;
        } props[4] = {
            {"matrix", n->matrix_count, 16, n->matrix},
            {"translation", n->translation_count, 3, n->translation},
            {"rotation", n->rotation_count, 4, n->rotation},
            {"scale", n->scale_count, 3, n->scale},
        };
        for (int p = 0; p < 4; p++) {
            if (props[p].given && props[p].given != props[p].want)
                return fail(im, TW_ERR_FORMAT, "nodes[%u].%s: has %u values, not %u", k,
                            props[p].what, props[p].given, props[p].want);
            if (props[p].given && !all_finite(props[p].values, props[p].want))
                return fail(im, TW_ERR_FORMAT, "nodes[%u].%s: a value is not finite", k,
                            props[p].what);
            /* Finite but huge values would overflow what is made of them
             * (boxes, Embree's SAH binning): a node moves or scales by at
             * most TW_TILES_MAX_MESH_COORD, and the placed meshes must end
             * within TW_TILES_MAX_COORD (build_scene()). */
            for (uint32_t e = 0; props[p].given && e < props[p].want; e++)
                if (fabs(props[p].values[e]) > TW_TILES_MAX_MESH_COORD)
                    return fail(im, TW_ERR_LIMIT, "nodes[%u].%s: %g is beyond +-%g", k,
                                props[p].what, props[p].values[e],
                                (double)TW_TILES_MAX_MESH_COORD);
        }
        if (n->matrix_count && (n->translation_count || n->rotation_count || n->scale_count))
            return fail(im, TW_ERR_FORMAT,
                        "nodes[%u]: has both a matrix and translation/rotation/scale", k);
        if (n->matrix_count && (n->matrix[3] != 0.0 || n->matrix[7] != 0.0 ||
                                n->matrix[11] != 0.0 || n->matrix[15] != 1.0))
            return fail(im, TW_ERR_FORMAT,
                        "nodes[%u].matrix: is not affine (its last row is not 0 0 0 1)", k);
        if (n->rotation_count) {
            const double *q = n->rotation;
            const double len = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
            if (!(len > 1e-6) || !isfinite(len))
                return fail(im, TW_ERR_FORMAT, "nodes[%u].rotation: is not a rotation (length %g)",
                            k, len);
        }
    }
    /* With one parent per node, a cycle is a chain of parents that never
     * reaches a root: walk up from every node, marking what is known to end
     * at a root. Linear time overall. */
    uint8_t *state = calloc(d->node_count ? d->node_count : 1, 1); /* 0 unknown, 1 on path, 2 rooted */
    if (!state)
        return fail(im, TW_ERR_NOMEM, "nodes: out of memory");
    int err = TW_OK;
    for (uint32_t k = 0; k < d->node_count && !err; k++) {
        uint32_t n = k;
        while (state[n] == 0 && parent[n] >= 0) {
            state[n] = 1;
            n = (uint32_t)parent[n];
        }
        if (state[n] == 1) {
            /* n was reached twice on this walk: it lies on a cycle. Name the
             * edge that closes it: n's parent lists n as a child. */
            const uint32_t p = (uint32_t)parent[n];
            uint32_t c = 0;
            while (d->nodes[p].children[c] != (int)n)
                c++;
            err = fail(im, TW_ERR_FORMAT,
                       "nodes[%u].children[%u]: nodes[%u] is an ancestor of nodes[%u] (a cycle)",
                       p, c, n, p);
            break;
        }
        for (uint32_t m = k; state[m] == 1; m = (uint32_t)parent[m]) {
            state[m] = 2;
            if (parent[m] < 0)
                break;
        }
        state[n] = 2;
    }
    free(state);
    return err;
}

/* Row-major affine 3x4 in double. */
static void node_local(const struct tw_gltf_doc_node *n, double out[12])
{
    if (n->matrix_count) {
        for (int r = 0; r < 3; r++)
            for (int c = 0; c < 4; c++)
                out[4 * r + c] = n->matrix[4 * c + r]; /* glTF is column-major */
        return;
    }
    double t[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
    if (n->translation_count)
        memcpy(t, n->translation, sizeof(t));
    if (n->rotation_count) {
        const double len = sqrt(n->rotation[0] * n->rotation[0] + n->rotation[1] * n->rotation[1] +
                                n->rotation[2] * n->rotation[2] + n->rotation[3] * n->rotation[3]);
        for (int k = 0; k < 4; k++)
            q[k] = n->rotation[k] / len;
    }
    if (n->scale_count)
        memcpy(s, n->scale, sizeof(s));
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    const double r[9] = {
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w),     2 * (x * z + y * w),
        2 * (x * y + z * w),     1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w),     2 * (y * z + x * w),     1 - 2 * (x * x + y * y),
    };
    for (int row = 0; row < 3; row++) {
        for (int c = 0; c < 3; c++)
            out[4 * row + c] = r[3 * row + c] * s[c];
        out[4 * row + 3] = t[row];
    }
}

static void compose(const double a[12], const double b[12], double out[12])
{
    for (int r = 0; r < 3; r++) {
        for (int c = 0; c < 4; c++) {
            double v = a[4 * r] * b[c] + a[4 * r + 1] * b[4 + c] + a[4 * r + 2] * b[8 + c];
            if (c == 3)
                v += a[4 * r + 3];
            out[4 * r + c] = v;
        }
    }
}

/* ---- base colour textures and vertex colours ------------------------------------ */

/* The renderer draws one colour per instance: a primitive whose base colour
 * varies (a baseColorTexture, COLOR_0) is split by colour into one primitive
 * per distinct colour, each triangle taking the texel at its centroid's UV
 * (nearest) times its mean vertex colour times the material's factor. A
 * texture that cannot be used costs a warning, never the import. */

#define MAX_SPLIT_COLOURS 64
/* A decoded image takes 4 bytes a pixel, however small its PNG: the size
 * its header gives is bounded before anything is decoded. */
#define MAX_IMAGE_DECODED_BYTES (64ull << 20)
/* Texture warnings shown per import; the rest are counted in one line. */
#define MAX_TEXTURE_WARNINGS 8

enum {
    WRAP_REPEAT = 10497,
    WRAP_CLAMP_TO_EDGE = 33071,
    WRAP_MIRRORED_REPEAT = 33648,
};

/* Where an image's bytes come from, which makes two images one: a file (by
 * its identity, however it is named; shared between the imports of a
 * manifest), a byte range of a buffer, or the bytes of a data: URI (by
 * content). */
enum image_source {
    SOURCE_FILE = 1,
    SOURCE_VIEW,
    SOURCE_DATA,
};

struct decoded_image {
    enum image_source source;
    uint64_t key[3];                  /* FILE: device, inode; VIEW: buffer, offset, length;
                                         DATA: hash, size */
    const uint8_t *bytes;             /* DATA: the document's, to compare */
    uint64_t hash;
    int state;                        /* 1 decoded, -1 unusable (warned once) */
    uint32_t width, height;
    uint8_t *rgba;
};

/* Decoded images by source: an open-addressing table of entries. */
struct tw_gltf_image_cache {
    struct decoded_image **entries;
    uint32_t count, cap;
    uint32_t *slots;                  /* entry indices; UINT32_MAX: empty */
    uint32_t size;                    /* a power of two */
};

static void image_cache_destroy(struct tw_gltf_image_cache *c)
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
    image_cache_destroy(shared->images);
    shared->images = NULL;
}

/* FNV-1a over n bytes. */
static uint64_t hash_data(const uint8_t *p, uint64_t n)
{
    uint64_t h = 0xcbf29ce484222325ull;
    for (uint64_t k = 0; k < n; k++)
        h = (h ^ p[k]) * 0x100000001b3ull;
    return h;
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

static bool same_source(const struct decoded_image *a, const struct decoded_image *b)
{
    if (a->source != b->source || a->hash != b->hash ||
        memcmp(a->key, b->key, sizeof(a->key)) != 0)
        return false;
    return a->source != SOURCE_DATA || memcmp(a->bytes, b->bytes, (size_t)a->key[1]) == 0;
}

/* The entry of probe's source in *cache (created on first use), or a new
 * one copied from probe with state 0; NULL when out of memory. */
static struct decoded_image *image_cache_find(struct tw_gltf_image_cache **cache,
                                              const struct decoded_image *probe)
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
        struct decoded_image **grown = realloc(c->entries, sizeof(*grown) * cap);
        if (!grown)
            return NULL;
        c->entries = grown;
        c->cap = cap;
    }
    struct decoded_image *e = malloc(sizeof(*e));
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

struct material_texture {
    int state;                        /* 0 not resolved, 1 textured, -1 none */
    const struct decoded_image *image;
    int32_t wrap_s, wrap_t;
    uint32_t texcoord;
    /* KHR_texture_transform (how quantised texture coordinates are
     * dequantised): uv' = offset + [[a, b], [c, d]] uv. */
    bool transformed;
    double offset[2], a, b, c, d;
};

/* A texture that cannot be used costs a warning, never the import; past
 * MAX_TEXTURE_WARNINGS of them they are only counted. */
static void warn_texture(struct importer *im, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static void warn_texture(struct importer *im, const char *fmt, ...)
{
    if (im->texture_warnings++ >= MAX_TEXTURE_WARNINGS)
        return;
    char text[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof(text), fmt, ap);
    va_end(ap);
    warn(im, "%s", text);
}

/* Decodes the PNG at bytes into out, within the limits: its header's size is
 * checked before anything is decoded. false (warned) if it cannot be used. */
static bool decode_png(struct importer *im, const char *what, const uint8_t *bytes, uint64_t size,
                       struct decoded_image *out)
{
    static const uint8_t signature[8] = {137, 80, 78, 71, 13, 10, 26, 10};
    if (size < 8 || memcmp(bytes, signature, 8) != 0) {
        warn_texture(im, "%s: is not a PNG image; its materials keep their base colour factor",
                     what);
        return false;
    }
    png_image png;
    memset(&png, 0, sizeof(png));
    png.version = PNG_IMAGE_VERSION;
    if (!png_image_begin_read_from_memory(&png, bytes, (size_t)size)) {
        warn_texture(im, "%s: cannot decode the PNG (%s); its materials keep their base colour "
                         "factor",
                     what, png.message);
        png_image_free(&png);
        return false;
    }
    const uint64_t decoded = 4ull * png.width * png.height;
    struct tw_gltf_shared *sh = im->shared;
    char a[32], b[32], c[32];
    if (decoded == 0 || decoded > MAX_IMAGE_DECODED_BYTES) {
        warn_texture(im, "%s: a %u x %u PNG would decode to %s, more than the limit of %s per "
                         "image; its materials keep their base colour factor",
                     what, png.width, png.height, byte_size(decoded, a, sizeof(a)),
                     byte_size(MAX_IMAGE_DECODED_BYTES, b, sizeof(b)));
        png_image_free(&png);
        return false;
    }
    if (sh->decoded_bytes + decoded > sh->max_decoded_bytes) {
        warn_texture(im, "%s: a %u x %u PNG would decode to %s, and the images decoded before "
                         "it hold %s: more than the limit of %s %s; its materials keep their "
                         "base colour factor",
                     what, png.width, png.height, byte_size(decoded, a, sizeof(a)),
                     byte_size(sh->decoded_bytes, b, sizeof(b)),
                     byte_size(sh->max_decoded_bytes, c, sizeof(c)),
                     im->own_shared ? "per import" : "per manifest");
        png_image_free(&png);
        return false;
    }
    png.format = PNG_FORMAT_RGBA;
    uint8_t *rgba = malloc((size_t)decoded);
    if (!rgba) {
        warn_texture(im, "%s: out of memory decoding the PNG; its materials keep their base "
                         "colour factor",
                     what);
        png_image_free(&png);
        return false;
    }
    /* Charged before decoding: a PNG that fails halfway cost its time. */
    sh->decoded_bytes += decoded;
    if (!png_image_finish_read(&png, NULL, rgba, 0, NULL)) {
        warn_texture(im, "%s: cannot decode the PNG (%s); its materials keep their base colour "
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
static struct decoded_image *load_image_file(struct importer *im, uint32_t index, const char *uri)
{
    char what[320], shown[224];
    snprintf(what, sizeof(what), "images[%u] \"%s\"", index,
             tw_log_escape(uri, shown, sizeof(shown)));
    if (im->dir_fd < 0) {
        warn_texture(im, "%s: external files are not allowed here; its materials keep their "
                         "base colour factor",
                     what);
        return NULL;
    }
    char *rel = uri_decode(uri);
    if (!rel) {
        warn_texture(im, "%s cannot be read: out of memory; its materials keep their base colour "
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
        warn_texture(im, "%s %s; its materials keep their base colour factor", what,
                     reason ? reason : "cannot be opened");
        return NULL;
    }
    struct decoded_image probe = {SOURCE_FILE, {(uint64_t)st.st_dev, (uint64_t)st.st_ino, 0},
                                  NULL, 0, 0, 0, 0, NULL};
    probe.hash = hash_words(probe.key, 3, SOURCE_FILE);
    struct decoded_image *e = image_cache_find(&im->shared->images, &probe);
    if (!e || e->state) {
        close(fd);
        if (!e)
            warn_texture(im, "%s: out of memory; its materials keep their base colour factor",
                         what);
        return e;
    }
    e->state = -1;
    uint8_t *bytes = NULL;
    size_t size = 0;
    char why[512];
    err = read_fd(im, fd, &bytes, &size, why, sizeof(why));
    close(fd);
    if (err) {
        warn_texture(im, "%s %s; its materials keep their base colour factor", what, why);
        return e;
    }
    if (decode_png(im, what, bytes, size, e))
        e->state = 1;
    free(bytes);
    return e;
}

/* Image index, resolved once per import and decoded once per source; NULL
 * (warned once per source) if unusable. */
static const struct decoded_image *load_image(struct importer *im, uint32_t index)
{
    if (im->image_of[index])
        return im->image_of[index]->state > 0 ? im->image_of[index] : NULL;
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_image *img = &d->images[index];
    struct decoded_image *e = NULL;
    char what[320];
    if (img->uri) {
        e = load_image_file(im, index, img->uri);
    } else if (img->buffer_view >= 0 || img->data) {
        struct decoded_image probe = {0};
        const uint8_t *bytes = NULL;
        uint64_t size = 0;
        if (img->buffer_view >= 0) {
            snprintf(what, sizeof(what), "images[%u] (bufferViews[%d])", index, img->buffer_view);
            if ((uint32_t)img->buffer_view >= d->buffer_view_count) {
                warn_texture(im, "%s: not a buffer view (%u); its materials keep their base "
                                 "colour factor",
                             what, d->buffer_view_count);
                return NULL;
            }
            /* Checked against its buffer by check_buffer_views(). */
            const struct tw_gltf_doc_buffer_view *v = &d->buffer_views[img->buffer_view];
            bytes = d->buffers[v->buffer].data;
            bytes = bytes ? bytes + v->byte_offset : bytes;
            size = bytes ? v->byte_length : 0;
            probe.source = SOURCE_VIEW;
            probe.key[0] = (uint64_t)v->buffer;
            probe.key[1] = v->byte_offset;
            probe.key[2] = v->byte_length;
            probe.hash = hash_words(probe.key, 3, SOURCE_VIEW);
        } else {
            snprintf(what, sizeof(what), "images[%u] (a data: URI)", index);
            bytes = img->data;
            size = img->size;
            probe.source = SOURCE_DATA;
            probe.bytes = bytes;
            probe.key[0] = hash_data(bytes, size);
            probe.key[1] = size;
            probe.hash = hash_words(probe.key, 2, SOURCE_DATA);
        }
        e = image_cache_find(&im->images, &probe);
        if (!e) {
            warn_texture(im, "%s: out of memory; its materials keep their base colour factor",
                         what);
        } else if (!e->state) {
            e->state = decode_png(im, what, bytes, size, e) ? 1 : -1;
        }
    } else {
        warn_texture(im, "images[%u]: has no data; its materials keep their base colour factor",
                     index);
    }
    if (!e)
        return NULL;
    im->image_of[index] = e;
    return e->state > 0 ? e : NULL;
}

/* The usable baseColorTexture of material index, resolved (and warned about)
 * once per import; NULL if none. */
static const struct material_texture *material_texture(struct importer *im, uint32_t index)
{
    struct material_texture *mt = &im->material_textures[index];
    if (mt->state)
        return mt->state > 0 ? mt : NULL;
    mt->state = -1;
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_material *mat = &d->materials[index];
    const int32_t t = mat->base_color_texture;
    if (t < 0)
        return NULL;
    if ((uint32_t)t >= d->texture_count) {
        warn_texture(im, "materials[%u].pbrMetallicRoughness.baseColorTexture: %d is not a texture "
                 "(%u); using the base colour factor",
             index, t, d->texture_count);
        return NULL;
    }
    if (mat->base_color_texcoord < 0 || mat->base_color_texcoord > 99) {
        warn_texture(im, "materials[%u].pbrMetallicRoughness.baseColorTexture.texCoord: %d is not "
                 "valid; using the base colour factor",
             index, mat->base_color_texcoord);
        return NULL;
    }
    const struct tw_gltf_doc_texture *tex = &d->textures[t];
    if (tex->source < 0 || (uint32_t)tex->source >= d->image_count) {
        warn_texture(im, "textures[%d].source: %d is not an image (%u); using the base colour factor", t,
             tex->source, d->image_count);
        return NULL;
    }
    mt->image = load_image(im, (uint32_t)tex->source);
    if (!mt->image)
        return NULL;
    mt->wrap_s = mt->wrap_t = WRAP_REPEAT;
    if (tex->sampler >= 0 && (uint32_t)tex->sampler < d->sampler_count) {
        mt->wrap_s = d->samplers[tex->sampler].wrap_s;
        mt->wrap_t = d->samplers[tex->sampler].wrap_t;
    }
    mt->texcoord = (uint32_t)mat->base_color_texcoord;
    if (mat->has_uv_transform) {
        const double r = mat->uv_rotation, sx = mat->uv_scale[0], sy = mat->uv_scale[1];
        const double xf[6] = {mat->uv_offset[0], mat->uv_offset[1], cos(r) * sx, sin(r) * sy,
                             -sin(r) * sx, cos(r) * sy};
        if (!all_finite(xf, 6)) {
            warn_texture(im, "materials[%u].pbrMetallicRoughness.baseColorTexture.extensions."
                     "KHR_texture_transform: a value is not finite; ignored",
                 index);
        } else {
            mt->transformed = true;
            mt->offset[0] = xf[0];
            mt->offset[1] = xf[1];
            mt->a = xf[2];
            mt->b = xf[3];
            mt->c = xf[4];
            mt->d = xf[5];
            if (mat->uv_texcoord >= 0 && mat->uv_texcoord <= 99)
                mt->texcoord = (uint32_t)mat->uv_texcoord;
        }
    }
    mt->state = 1;
    return mt;
}

/* The accessor of attribute name if it is usable as texture coordinates
 * (want 2) or colours (want 3: VEC3 or VEC4) of nv vertices, else -1
 * (warned if present). */
static int32_t colour_attribute(struct importer *im, uint32_t m, uint32_t k, const char *name,
                                uint32_t want, uint32_t nv)
{
    const struct tw_gltf_doc_primitive *p = &im->doc->meshes[m].primitives[k];
    const int32_t acc = find_attribute(p, name);
    if (acc < 0)
        return -1;
    const struct tw_gltf_doc_accessor *a = &im->doc->accessors[acc];
    const bool type_ok = want == 2 ? a->type == TYPE_VEC2
                                   : (a->type == TYPE_VEC3 || a->type == TYPE_VEC4);
    /* Texture coordinates may be any 8- or 16-bit integers, normalized or
     * not (KHR_mesh_quantization); colours only normalized unsigned ones. */
    const bool comp_ok = a->component_type == COMP_FLOAT ||
                         (want == 2 && is_integer(a->component_type)) ||
                         ((a->component_type == COMP_UNSIGNED_BYTE ||
                           a->component_type == COMP_UNSIGNED_SHORT) &&
                          a->normalized);
    if (!type_ok || !comp_ok || a->count != nv) {
        warn_texture(im, "meshes[%u].primitives[%u].attributes.%s: accessors[%d] is not %u %s of "
                         "FLOAT "
                 "or %s; ignored",
             m, k, name, acc, nv, want == 2 ? "VEC2" : "VEC3/VEC4",
             want == 2 ? "8- or 16-bit integers" : "normalized UNSIGNED_BYTE/SHORT");
        return -1;
    }
    return acc;
}

static uint32_t wrap_texel(float coord, int32_t mode, uint32_t size)
{
    double c = isfinite(coord) ? coord : 0.0;
    switch (mode) {
    case WRAP_CLAMP_TO_EDGE:
        c = fmin(fmax(c, 0.0), 1.0);
        break;
    case WRAP_MIRRORED_REPEAT:
        c -= 2.0 * floor(c / 2.0);
        if (c > 1.0)
            c = 2.0 - c;
        break;
    default:
        c -= floor(c);
        break;
    }
    const double t = floor(c * size);
    return t <= 0.0 ? 0 : t >= size - 1 ? size - 1 : (uint32_t)t;
}

/* Materials made of baked colours, shared by every primitive of the scene:
 * an open-addressing table from RGBA8 to material index. */
struct palette {
    uint32_t *keys;
    uint32_t *materials;              /* UINT32_MAX: empty slot */
    uint32_t size;                    /* a power of two */
    uint32_t count;
    uint32_t material_capacity;       /* of sc->materials */
    uint32_t primitive_capacity;      /* of sc->primitives */
};

static void palette_finish(struct palette *pal)
{
    free(pal->keys);
    free(pal->materials);
}

static uint32_t palette_hash(uint32_t key)
{
    key ^= key >> 16;
    key *= 0x7feb352du;
    key ^= key >> 15;
    key *= 0x846ca68bu;
    return key ^ key >> 16;
}

/* The material of colour rgba (0..1), added to sc if new. */
static int palette_material(struct palette *pal, struct tw_gltf_scene *sc, const float rgba[4],
                            uint32_t *out)
{
    uint8_t q[4];
    for (int c = 0; c < 4; c++)
        q[c] = (uint8_t)lrintf(fminf(fmaxf(rgba[c], 0.0f), 1.0f) * 255.0f);
    const uint32_t key = (uint32_t)q[0] << 24 | (uint32_t)q[1] << 16 | (uint32_t)q[2] << 8 | q[3];
    if (2 * (pal->count + 1) > pal->size) {
        const uint32_t size = pal->size ? 2 * pal->size : 64;
        uint32_t *keys = malloc(sizeof(*keys) * size), *materials = malloc(sizeof(*materials) * size);
        if (!keys || !materials) {
            free(keys);
            free(materials);
            return TW_ERR_NOMEM;
        }
        for (uint32_t s = 0; s < size; s++)
            materials[s] = UINT32_MAX;
        for (uint32_t s = 0; s < pal->size; s++) {
            if (pal->materials[s] == UINT32_MAX)
                continue;
            uint32_t h = palette_hash(pal->keys[s]) & (size - 1);
            while (materials[h] != UINT32_MAX)
                h = (h + 1) & (size - 1);
            keys[h] = pal->keys[s];
            materials[h] = pal->materials[s];
        }
        palette_finish(pal);
        pal->keys = keys;
        pal->materials = materials;
        pal->size = size;
    }
    uint32_t h = palette_hash(key) & (pal->size - 1);
    while (pal->materials[h] != UINT32_MAX) {
        if (pal->keys[h] == key) {
            *out = pal->materials[h];
            return TW_OK;
        }
        h = (h + 1) & (pal->size - 1);
    }
    if (sc->material_count == pal->material_capacity) {
        if (pal->material_capacity > UINT32_MAX / 2)
            return TW_ERR_LIMIT;
        const uint32_t capacity = 2 * pal->material_capacity;
        struct tw_material *grown = realloc(sc->materials, sizeof(*grown) * capacity);
        if (!grown)
            return TW_ERR_NOMEM;
        sc->materials = grown;
        pal->material_capacity = capacity;
    }
    struct tw_material *mat = &sc->materials[sc->material_count];
    memset(mat, 0, sizeof(*mat));
    for (int c = 0; c < 4; c++)
        mat->base_color[c] = (float)q[c] / 255.0f;
    pal->keys[h] = key;
    pal->materials[h] = sc->material_count;
    pal->count++;
    *out = sc->material_count++;
    return TW_OK;
}

/* Appends prim (taking its arrays) to sc as the next primitive of gm. On
 * failure prim's arrays are freed. */
static int append_primitive(struct palette *pal, struct tw_gltf_scene *sc, struct tw_gltf_mesh *gm,
                            struct tw_gltf_primitive *prim)
{
    if (sc->primitive_count == pal->primitive_capacity) {
        const uint32_t capacity = pal->primitive_capacity > UINT32_MAX / 2
                                      ? UINT32_MAX
                                      : 2 * pal->primitive_capacity + 1;
        struct tw_gltf_primitive *grown =
            capacity > sc->primitive_count
                ? realloc(sc->primitives, sizeof(*grown) * (size_t)capacity)
                : NULL;
        if (!grown) {
            free(prim->positions);
            free(prim->normals);
            free(prim->indices);
            memset(prim, 0, sizeof(*prim));
            return TW_ERR_NOMEM;
        }
        sc->primitives = grown;
        pal->primitive_capacity = capacity;
    }
    sc->primitives[sc->primitive_count++] = *prim;
    sc->vertex_count += prim->vertex_count;
    gm->primitive_count++;
    memset(prim, 0, sizeof(*prim));
    return TW_OK;
}

/* The triangles of whole listed in order[0, count) as a primitive of their
 * own, with only the vertices they use (remap: nv entries of UINT32_MAX,
 * left so). */
static int extract_triangles(const struct tw_gltf_primitive *whole, const uint32_t *order,
                             uint32_t count, uint32_t *remap, struct tw_gltf_primitive *out)
{
    memset(out, 0, sizeof(*out));
    out->indices = malloc(sizeof(uint32_t) * 3 * (size_t)count);
    if (!out->indices)
        return TW_ERR_NOMEM;
    uint32_t nv = 0;
    for (uint32_t t = 0; t < count; t++) {
        for (int c = 0; c < 3; c++) {
            const uint32_t v = whole->indices[3 * (size_t)order[t] + c];
            if (remap[v] == UINT32_MAX)
                remap[v] = nv++;
            out->indices[3 * (size_t)t + c] = remap[v];
        }
    }
    out->positions = malloc(sizeof(float) * 3 * (size_t)nv);
    out->normals = whole->normals ? malloc(sizeof(float) * 3 * (size_t)nv) : NULL;
    const bool ok = out->positions && (out->normals || !whole->normals);
    out->box = tw_box_empty();
    for (uint32_t t = 0; t < count; t++) {
        for (int c = 0; c < 3; c++) {
            const uint32_t v = whole->indices[3 * (size_t)order[t] + c];
            if (remap[v] == UINT32_MAX)
                continue;
            if (ok) {
                const uint32_t w = remap[v];
                memcpy(out->positions + 3 * (size_t)w, whole->positions + 3 * (size_t)v,
                       3 * sizeof(float));
                if (whole->normals)
                    memcpy(out->normals + 3 * (size_t)w, whole->normals + 3 * (size_t)v,
                           3 * sizeof(float));
                tw_box_add_point(&out->box, whole->positions + 3 * (size_t)v);
            }
            remap[v] = UINT32_MAX;
        }
    }
    out->vertex_count = nv;
    out->triangle_count = count;
    out->material = whole->material;
    if (!ok) {
        free(out->positions);
        free(out->normals);
        free(out->indices);
        memset(out, 0, sizeof(*out));
        return TW_ERR_NOMEM;
    }
    return TW_OK;
}

static float triangle_area(const float *positions, const uint32_t *ix)
{
    const float *a = positions + 3 * (size_t)ix[0], *b = positions + 3 * (size_t)ix[1],
                *c = positions + 3 * (size_t)ix[2];
    const float u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const float v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const float x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2],
                z = u[0] * v[1] - u[1] * v[0];
    const float area = 0.5f * sqrtf(x * x + y * y + z * z);
    return isfinite(area) ? area : 0.0f;
}

/* Appends the converted primitive k of mesh m to sc, split by colour when
 * its material has a usable baseColorTexture or it has COLOR_0. Takes
 * prim's arrays in every case. */
static int add_primitive(struct importer *im, uint32_t m, uint32_t k, struct palette *pal,
                         struct tw_gltf_scene *sc, struct tw_gltf_mesh *gm,
                         struct tw_gltf_primitive *prim)
{
    const struct tw_gltf_doc *d = im->doc;
    const uint32_t material = prim->material; /* the file's, or grey */
    const struct material_texture *tex =
        material < d->material_count ? material_texture(im, material) : NULL;
    const uint32_t nv = prim->vertex_count, tris = prim->triangle_count;
    int32_t uv_acc = -1;
    if (tex) {
        char name[32];
        snprintf(name, sizeof(name), "TEXCOORD_%u", tex->texcoord);
        uv_acc = colour_attribute(im, m, k, name, 2, nv);
        if (uv_acc < 0 && find_attribute(&d->meshes[m].primitives[k], name) < 0)
            warn_texture(im, "meshes[%u].primitives[%u]: materials[%u] has a baseColorTexture but "
                             "the "
                     "primitive has no %s; using the base colour factor",
                 m, k, material, name);
    }
    const int32_t colour_acc = colour_attribute(im, m, k, "COLOR_0", 3, nv);
    if (uv_acc < 0 && colour_acc < 0)
        return append_primitive(pal, sc, gm, prim);

    int err = TW_OK;
    float *uv = NULL, *vcol = NULL, *tri_colour = NULL;
    uint32_t *order = NULL, *remap = NULL;
    uint8_t *slot = NULL;
    uint32_t colour_count = 0, first[MAX_SPLIT_COLOURS + 2], materials[MAX_SPLIT_COLOURS + 1];
    uint32_t keys[MAX_SPLIT_COLOURS + 1];
    if (uv_acc >= 0 && !(uv = malloc(sizeof(float) * 2 * (size_t)nv)))
        goto nomem;
    if (colour_acc >= 0 && !(vcol = malloc(sizeof(float) * 4 * (size_t)nv)))
        goto nomem;
    tri_colour = malloc(sizeof(float) * 3 * (size_t)tris);
    slot = malloc(tris);
    if (!tri_colour || !slot)
        goto nomem;
    if (uv && (err = read_floats(im, (uint32_t)uv_acc, 2, uv)))
        goto out;
    if (vcol) {
        const bool rgba = d->accessors[colour_acc].type == TYPE_VEC4;
        if ((err = read_floats(im, (uint32_t)colour_acc, rgba ? 4 : 3, vcol)))
            goto out;
        if (!rgba) /* spread VEC3 to four floats, back to front */
            for (uint32_t v = nv; v-- > 0;) {
                for (int c = 2; c >= 0; c--)
                    vcol[4 * (size_t)v + c] = vcol[3 * (size_t)v + c];
                vcol[4 * (size_t)v + 3] = 1.0f;
            }
    }

    /* A copy: palette_material() may move sc->materials. */
    float factor[4];
    memcpy(factor, sc->materials[material].base_color, sizeof(factor));
    for (uint32_t t = 0; t < tris; t++) {
        const uint32_t *ix = prim->indices + 3 * (size_t)t;
        float c[3] = {factor[0], factor[1], factor[2]};
        if (uv) {
            float u = 0.0f, v = 0.0f;
            for (int e = 0; e < 3; e++) {
                u += uv[2 * (size_t)ix[e]] / 3.0f;
                v += uv[2 * (size_t)ix[e] + 1] / 3.0f;
            }
            if (tex->transformed) {
                const double tu = tex->offset[0] + tex->a * u + tex->b * v;
                const double tv = tex->offset[1] + tex->c * u + tex->d * v;
                u = isfinite(tu) ? (float)fmax(fmin(tu, 1e9), -1e9) : 0.0f;
                v = isfinite(tv) ? (float)fmax(fmin(tv, 1e9), -1e9) : 0.0f;
            }
            const struct decoded_image *img = tex->image;
            const uint32_t x = wrap_texel(u, tex->wrap_s, img->width);
            const uint32_t y = wrap_texel(v, tex->wrap_t, img->height);
            const uint8_t *texel = img->rgba + 4 * ((size_t)y * img->width + x);
            for (int e = 0; e < 3; e++)
                c[e] *= (float)texel[e] / 255.0f;
        }
        if (vcol) {
            for (int e = 0; e < 3; e++) {
                const float mean = (vcol[4 * (size_t)ix[0] + e] + vcol[4 * (size_t)ix[1] + e] +
                                    vcol[4 * (size_t)ix[2] + e]) / 3.0f;
                c[e] *= isfinite(mean) ? fminf(fmaxf(mean, 0.0f), 1.0f) : 1.0f;
            }
        }
        for (int e = 0; e < 3; e++)
            tri_colour[3 * (size_t)t + e] = fminf(fmaxf(c[e], 0.0f), 1.0f);
    }

    /* Group by 8-bit colour. Palettes with gradients (Kenney's kits) give
     * more colours than draws are worth: coarsen to 7, 6, ... 4 bits per
     * channel before giving up; a group's colour is its area-weighted mean. */
    for (int bits = 8; bits >= 4; bits--) {
        colour_count = 0;
        for (uint32_t t = 0; t < tris && colour_count <= MAX_SPLIT_COLOURS; t++) {
            uint32_t key = 0;
            for (int e = 0; e < 3; e++)
                key = key << 8 |
                      (uint32_t)lrintf(tri_colour[3 * (size_t)t + e] * 255.0f) >> (8 - bits);
            uint32_t s = 0;
            while (s < colour_count && keys[s] != key)
                s++;
            if (s == colour_count)
                keys[colour_count++] = key;
            slot[t] = (uint8_t)s;
        }
        if (colour_count <= MAX_SPLIT_COLOURS)
            break;
    }
    if (colour_count > MAX_SPLIT_COLOURS) {
        /* Too many colours for one draw each: one mean colour. */
        colour_count = 1;
        memset(slot, 0, tris);
    }
    {
        double sum[MAX_SPLIT_COLOURS + 1][4];
        memset(sum, 0, sizeof(sum));
        for (uint32_t t = 0; t < tris; t++) {
            double area = triangle_area(prim->positions, prim->indices + 3 * (size_t)t);
            if (!(area > 0.0))
                area = 1e-30;
            for (int e = 0; e < 3; e++)
                sum[slot[t]][e] += area * tri_colour[3 * (size_t)t + e];
            sum[slot[t]][3] += area;
        }
        for (uint32_t s = 0; s < colour_count; s++) {
            const float rgba[4] = {(float)(sum[s][0] / sum[s][3]), (float)(sum[s][1] / sum[s][3]),
                                   (float)(sum[s][2] / sum[s][3]), factor[3]};
            if ((err = palette_material(pal, sc, rgba, &materials[s])))
                goto out;
        }
    }
    if (colour_count == 1) {
        prim->material = materials[0];
        err = append_primitive(pal, sc, gm, prim);
        goto out;
    }
    /* Triangles grouped by colour, in their order within each group. */
    order = malloc(sizeof(uint32_t) * (size_t)tris);
    remap = malloc(sizeof(uint32_t) * (size_t)nv);
    if (!order || !remap)
        goto nomem;
    for (uint32_t v = 0; v < nv; v++)
        remap[v] = UINT32_MAX;
    memset(first, 0, sizeof(first));
    for (uint32_t t = 0; t < tris; t++)
        first[slot[t] + 1]++;
    for (uint32_t s = 1; s <= colour_count; s++)
        first[s] += first[s - 1];
    {
        uint32_t next[MAX_SPLIT_COLOURS + 2];
        memcpy(next, first, sizeof(next));
        for (uint32_t t = 0; t < tris; t++)
            order[next[slot[t]]++] = t;
    }
    for (uint32_t s = 0; s < colour_count; s++) {
        const uint32_t end = first[s + 1];
        struct tw_gltf_primitive part;
        if ((err = extract_triangles(prim, order + first[s], end - first[s], remap, &part)))
            goto out;
        part.material = materials[s];
        if ((err = append_primitive(pal, sc, gm, &part)))
            goto out;
    }
    goto out;
nomem:
    err = TW_ERR_NOMEM;
out:
    if (err == TW_ERR_NOMEM)
        fail(im, err, "meshes[%u].primitives[%u]: out of memory splitting by colour", m, k);
    else if (err == TW_ERR_LIMIT)
        fail(im, err, "materials: more than 2^31 colours");
    /* prim's arrays, unless append_primitive() took them. */
    free(prim->positions);
    free(prim->normals);
    free(prim->indices);
    memset(prim, 0, sizeof(*prim));
    free(uv);
    free(vcol);
    free(tri_colour);
    free(order);
    free(remap);
    free(slot);
    return err;
}

/* ---- the import ----------------------------------------------------------------- */

void tw_gltf_scene_destroy(struct tw_gltf_scene *scene)
{
    if (!scene)
        return;
    for (uint32_t k = 0; k < scene->primitive_count; k++) {
        free(scene->primitives[k].positions);
        free(scene->primitives[k].normals);
        free(scene->primitives[k].indices);
    }
    free(scene->primitives);
    free(scene->meshes);
    free(scene->materials);
    free(scene->instances);
    free(scene->source);
    free(scene);
}

static char *copy_string(const char *s)
{
    const size_t n = strlen(s) + 1;
    char *c = malloc(n);
    if (c)
        memcpy(c, s, n);
    return c;
}

/* The extensions a document may require: those read here, and those whose
 * absence changes only what this importer does not draw anyway (material
 * models, lights, image formats: a texture that is not a PNG leaves the base
 * colour, with a warning). Any other name, a misspelt one included, may
 * change geometry (compression, GPU instancing) and is refused: glTF 2.0
 * §3.12, a loader MUST NOT load a document requiring an extension it does
 * not support. */
static bool supported_extension(const char *name)
{
    static const char *const names[] = {
        "KHR_mesh_quantization",           /* integer vertex attributes, dequantised */
        "KHR_texture_transform",           /* read for base colour textures */
        "KHR_materials_anisotropy", "KHR_materials_clearcoat", "KHR_materials_diffuse_transmission",
        "KHR_materials_dispersion", "KHR_materials_emissive_strength", "KHR_materials_ior",
        "KHR_materials_iridescence", "KHR_materials_pbrSpecularGlossiness",
        "KHR_materials_sheen", "KHR_materials_specular", "KHR_materials_transmission",
        "KHR_materials_unlit", "KHR_materials_variants", "KHR_materials_volume",
        "KHR_lights_punctual", "KHR_texture_basisu", "EXT_texture_webp", "EXT_texture_avif",
        "KHR_xmp_json_ld", NULL};
    for (const char *const *n = names; *n; n++)
        if (strcmp(name, *n) == 0)
            return true;
    return false;
}

/* Builds the scene from a checked document. Linear in the document's size:
 * every node is visited once, every mesh's triangles counted once. */
static int build_scene(struct importer *im, const int32_t *parent, struct tw_gltf_scene *sc)
{
    const struct tw_gltf_doc *d = im->doc;
    int err = TW_OK;
    uint32_t *stack = NULL, *mesh_slot = NULL, *instance_node = NULL;
    uint64_t *mesh_tris = NULL;
    uint8_t *listed = NULL;
    double *world = NULL;
    struct palette pal = {0};

    /* Which nodes the scene starts from. */
    const int *roots = NULL;
    uint32_t root_count = 0;
    int32_t scene_index = d->default_scene;
    if (scene_index < -1 || (scene_index >= 0 && (uint32_t)scene_index >= d->scene_count))
        return fail(im, TW_ERR_FORMAT, "scene: %d is not a scene (%u)", scene_index,
                    d->scene_count);
    if (scene_index < 0 && d->scene_count > 0)
        scene_index = 0;
    const size_t nodes = d->node_count ? d->node_count : 1;
    const size_t meshes = d->mesh_count ? d->mesh_count : 1;
    stack = malloc(sizeof(*stack) * nodes);
    world = malloc(sizeof(*world) * 12 * nodes);
    mesh_slot = malloc(sizeof(*mesh_slot) * meshes);
    mesh_tris = malloc(sizeof(*mesh_tris) * meshes);
    instance_node = malloc(sizeof(*instance_node) * nodes);
    listed = calloc(nodes, 1);
    sc->instances = malloc(sizeof(*sc->instances) * nodes);
    if (!stack || !world || !mesh_slot || !mesh_tris || !instance_node || !listed ||
        !sc->instances) {
        err = fail(im, TW_ERR_NOMEM, "nodes: out of memory");
        goto out;
    }
    uint32_t top = 0;
    if (scene_index >= 0) {
        roots = d->scenes[scene_index].nodes;
        root_count = d->scenes[scene_index].node_count;
        for (uint32_t k = 0; k < root_count; k++) {
            const int n = roots[k];
            if (n < 0 || (uint32_t)n >= d->node_count) {
                err = fail(im, TW_ERR_FORMAT, "scenes[%d].nodes[%u]: %d is not a node (%u)",
                           scene_index, k, n, d->node_count);
                goto out;
            }
            if (parent[n] >= 0) {
                err = fail(im, TW_ERR_FORMAT,
                           "scenes[%d].nodes[%u]: nodes[%d] is not a root (a child of nodes[%d])",
                           scene_index, k, n, parent[n]);
                goto out;
            }
            if (listed[n]) {
                err = fail(im, TW_ERR_FORMAT, "scenes[%d].nodes[%u]: nodes[%d] is listed twice",
                           scene_index, k, n);
                goto out;
            }
            listed[n] = 1;
            stack[top++] = (uint32_t)n;
        }
    } else {
        for (uint32_t n = 0; n < d->node_count; n++)
            if (parent[n] < 0)
                stack[top++] = n;
    }
    for (uint32_t k = 0; k < top; k++)
        node_local(&d->nodes[stack[k]], world + 12 * (size_t)stack[k]);
    /* Pop in document order. */
    for (uint32_t a = 0, b = top; a + 1 < b; a++, b--) {
        const uint32_t t = stack[a];
        stack[a] = stack[b - 1];
        stack[b - 1] = t;
    }
    for (uint32_t m = 0; m < d->mesh_count; m++) {
        mesh_slot[m] = UINT32_MAX;
        mesh_tris[m] = UINT64_MAX; /* not counted yet */
    }

    /* Depth first; every node is pushed at most once (one parent, no cycle). */
    uint64_t drawn = 0, vertices = 0, converted = 0;
    while (top > 0) {
        const uint32_t n = stack[--top];
        const struct tw_gltf_doc_node *node = &d->nodes[n];
        const double *w = world + 12 * (size_t)n;
        for (uint32_t c = node->child_count; c-- > 0;) {
            const uint32_t child = (uint32_t)node->children[c];
            double local[12];
            node_local(&d->nodes[child], local);
            compose(w, local, world + 12 * (size_t)child);
            stack[top++] = child;
        }
        if (node->mesh < 0)
            continue;
        const uint32_t m = (uint32_t)node->mesh;
        if (mesh_tris[m] == UINT64_MAX) {
            uint64_t tris = 0;
            for (uint32_t k = 0; k < d->meshes[m].primitive_count; k++) {
                uint64_t t;
                if ((err = primitive_triangles(im, m, k, &t)))
                    goto out;
                tris += t;
            }
            mesh_tris[m] = tris;
            if (tris == 0)
                continue; /* draws nothing */
            mesh_slot[m] = sc->mesh_count++;
            sc->unique_triangles += tris;
            /* Accessors without a buffer view hold any count in no bytes:
             * bound vertices too before anything is allocated for them, and
             * what converting takes by what was read. */
            for (uint32_t k = 0; k < d->meshes[m].primitive_count; k++) {
                const struct tw_gltf_doc_primitive *p = &d->meshes[m].primitives[k];
                const int32_t pos = find_attribute(p, "POSITION");
                if (pos < 0 || !draws_triangles(p))
                    continue;
                const uint64_t nv = d->accessors[pos].count;
                uint64_t t;
                primitive_triangles(im, m, k, &t);
                vertices += nv;
                converted += 12 * nv * (find_attribute(p, "NORMAL") >= 0 ? 2 : 1) + 12 * t +
                             (p->indices >= 0 ? 4 * d->accessors[p->indices].count : 0);
            }
            if (vertices > 3 * im->settings.max_triangles) {
                err = fail(im, TW_ERR_LIMIT,
                           "meshes[%u]: the scene's meshes have more than %llu vertices (3 per "
                           "triangle of the limit)",
                           m, (unsigned long long)(3 * im->settings.max_triangles));
                goto out;
            }
            if (sc->unique_triangles > im->settings.max_triangles) {
                err = fail(im, TW_ERR_LIMIT,
                           "meshes: more than the limit of %llu triangles",
                           (unsigned long long)im->settings.max_triangles);
                goto out;
            }
            const uint64_t allowed = MEMORY_BASE + MEMORY_PER_BYTE * im->bytes_read;
            if (converted > allowed) {
                char a[32], b[32];
                err = fail(im, TW_ERR_LIMIT,
                           "meshes[%u]: converting the scene's meshes would take %s, more than "
                           "the %s allowed for %llu bytes of file and buffers (64 MiB + 32 "
                           "bytes per byte)",
                           m, byte_size(converted, a, sizeof(a)), byte_size(allowed, b, sizeof(b)),
                           (unsigned long long)im->bytes_read);
                goto out;
            }
        }
        if (mesh_tris[m] == 0)
            continue;
        struct tw_gltf_instance *in = &sc->instances[sc->instance_count];
        for (int k = 0; k < 12; k++) {
            /* Checked in double before the conversion to float. */
            if (!isfinite(w[k])) {
                err = fail(im, TW_ERR_FORMAT,
                           "nodes[%u]: its transform, composed with its ancestors', is not "
                           "finite",
                           n);
                goto out;
            }
            if (fabs(w[k]) > TW_TILES_MAX_COORD) {
                err = fail(im, TW_ERR_LIMIT,
                           "nodes[%u]: its transform, composed with its ancestors', has %s %g, "
                           "beyond +-%g",
                           n, k % 4 == 3 ? "a translation of" : "a scale or rotation term of",
                           w[k], (double)TW_TILES_MAX_COORD);
                goto out;
            }
            in->transform[k] = (float)w[k];
        }
        in->mesh = mesh_slot[m];
        instance_node[sc->instance_count] = n;
        sc->instance_count++;
        /* Drawn triangles are counted from the document's counts, before
         * anything is converted, so that the limit holds first. */
        drawn += mesh_tris[m];
        if (drawn > im->settings.max_triangles) {
            err = fail(im, TW_ERR_LIMIT,
                       "nodes[%u]: the scene draws more than the limit of %llu triangles", n,
                       (unsigned long long)im->settings.max_triangles);
            goto out;
        }
    }
    if (sc->instance_count == 0) {
        err = fail(im, TW_ERR_FORMAT, "%s: draws nothing (no node with a triangle mesh)",
                   scene_index >= 0 ? "the scene" : "the document");
        goto out;
    }
    sc->triangle_count = drawn;

    /* Materials: the file's, then grey for primitives without one. */
    sc->material_count = d->material_count + 1;
    sc->materials = malloc(sizeof(*sc->materials) * sc->material_count);
    if (!sc->materials) {
        err = fail(im, TW_ERR_NOMEM, "materials: out of memory");
        goto out;
    }
    for (uint32_t k = 0; k < d->material_count; k++) {
        const struct tw_gltf_doc_material *mat = &d->materials[k];
        if (mat->base_color_count != 4 || !all_finite(mat->base_color, 4)) {
            err = fail(im, TW_ERR_FORMAT,
                       "materials[%u].pbrMetallicRoughness.baseColorFactor: must be 4 finite "
                       "numbers",
                       k);
            goto out;
        }
        for (int c = 0; c < 4; c++)
            sc->materials[k].base_color[c] = (float)fmin(fmax(mat->base_color[c], 0.0), 1.0);
    }
    memcpy(sc->materials[d->material_count].base_color, default_grey, sizeof(default_grey));

    /* Meshes, in slot order; colour splits append more primitives and
     * materials (after grey). */
    uint32_t primitive_total = 0;
    for (uint32_t m = 0; m < d->mesh_count; m++)
        if (mesh_slot[m] != UINT32_MAX)
            primitive_total += d->meshes[m].primitive_count;
    pal.material_capacity = sc->material_count;
    pal.primitive_capacity = primitive_total;
    sc->meshes = calloc(sc->mesh_count, sizeof(*sc->meshes));
    sc->primitives = calloc(primitive_total, sizeof(*sc->primitives));
    if (!sc->meshes || !sc->primitives) {
        err = fail(im, TW_ERR_NOMEM, "meshes: out of memory");
        goto out;
    }
    for (uint32_t m = 0; m < d->mesh_count; m++) {
        const uint32_t slot = mesh_slot[m];
        if (slot == UINT32_MAX)
            continue;
        struct tw_gltf_mesh *gm = &sc->meshes[slot];
        gm->first_primitive = sc->primitive_count;
        for (uint32_t k = 0; k < d->meshes[m].primitive_count; k++) {
            struct tw_gltf_primitive prim = {0};
            err = convert_primitive(im, m, k, d->material_count, &prim);
            if (prim.triangle_count == 0 || err) {
                free(prim.positions);
                free(prim.normals);
                free(prim.indices);
                if (err)
                    goto out;
                continue;
            }
            if ((err = add_primitive(im, m, k, &pal, sc, gm, &prim)))
                goto out;
        }
    }
    bool grey_used = false;
    for (uint32_t k = 0; k < sc->primitive_count; k++)
        grey_used |= sc->primitives[k].material == d->material_count;
    if (!grey_used) {
        /* Drop grey: baked colours move down one. */
        const uint32_t grey = d->material_count;
        memmove(sc->materials + grey, sc->materials + grey + 1,
                sizeof(*sc->materials) * (sc->material_count - grey - 1));
        sc->material_count--;
        for (uint32_t k = 0; k < sc->primitive_count; k++)
            if (sc->primitives[k].material > grey)
                sc->primitives[k].material--;
    }

    /* Every drawn mesh, placed, within reach of its tile (tiles.h,
     * TW_TILES_MAX_COORD): named by the node that places it. */
    sc->bounds = tw_box_empty();
    for (uint32_t k = 0; k < sc->instance_count; k++) {
        const struct tw_gltf_instance *in = &sc->instances[k];
        const struct tw_gltf_mesh *gm = &sc->meshes[in->mesh];
        struct tw_box placed = tw_box_empty();
        for (uint32_t p = 0; p < gm->primitive_count; p++) {
            struct tw_box b = tw_box_transform(&sc->primitives[gm->first_primitive + p].box,
                                               in->transform);
            tw_box_add_box(&placed, &b);
        }
        for (int a = 0; a < 3 && !tw_box_is_empty(&placed); a++) {
            const float lo = placed.min[a], hi = placed.max[a];
            if (!(lo >= -TW_TILES_MAX_COORD) || !(hi <= TW_TILES_MAX_COORD)) {
                err = fail(im, TW_ERR_LIMIT,
                           "nodes[%u]: its mesh, placed by the node's transform composed with "
                           "its ancestors', reaches %c = %g m, beyond +-%g m",
                           instance_node[k], "xyz"[a], !(lo >= -TW_TILES_MAX_COORD) ? lo : hi,
                           (double)TW_TILES_MAX_COORD);
                goto out;
            }
        }
        tw_box_add_box(&sc->bounds, &placed);
    }
    for (int k = 0; k < 3; k++) {
        if (!isfinite(sc->bounds.min[k]) || !isfinite(sc->bounds.max[k])) {
            err = fail(im, TW_ERR_FORMAT, "the scene's bounds are not finite");
            goto out;
        }
    }
out:
    palette_finish(&pal);
    free(stack);
    free(world);
    free(mesh_slot);
    free(mesh_tris);
    free(instance_node);
    free(listed);
    return err;
}

/* Bytes that importing a document with this JSON will hold, from the scan
 * alone: nlohmann::json's tree (measured: about 24 bytes per value, 64 more
 * per object, 96 per member, 48 per string plus its text), tinygltf's and
 * the shim's objects (their sizes, from the shim), tinygltf's copies of the
 * extras and extensions as tinygltf::Value trees, string copies, and what
 * this file keeps per node and per primitive. An overestimate: the tree is
 * freed before the shim copies anything. */
static uint64_t memory_estimate(const struct tw_gltf_scan *s)
{
    uint64_t bytes = 32 * s->values + 64 * s->objects + 96 * s->members + 48 * s->strings +
                     4 * s->string_bytes + 256 * s->extension_values;
    for (int k = 0; k < TW_GLTF_KIND_COUNT; k++)
        bytes += s->counts[k] * tw_gltf_shim_element_bytes((enum tw_gltf_kind)k);
    /* build_scene(): parent, stack, world transform, instance, node per node. */
    bytes += s->counts[TW_GLTF_NODES] * (4 + 4 + 96 + sizeof(struct tw_gltf_instance) + 4 + 1);
    bytes += s->counts[TW_GLTF_MATERIALS] * (sizeof(struct tw_material) +
                                             sizeof(struct material_texture));
    bytes += s->counts[TW_GLTF_IMAGES] * (sizeof(struct decoded_image) + 2 * sizeof(void *));
    bytes += s->counts[TW_GLTF_ACCESSORS] * sizeof(struct accessor_facts);
    bytes += s->counts[TW_GLTF_PRIMITIVES] * sizeof(struct tw_gltf_primitive);
    return bytes;
}

static const char *extension_advice(const char *name)
{
    if (strcmp(name, "KHR_draco_mesh_compression") == 0)
        return " (Draco-compressed geometry: decompress it first, e.g. gltf-transform copy, or "
               "gltfpack without -cc)";
    if (strcmp(name, "EXT_meshopt_compression") == 0 ||
        strcmp(name, "KHR_meshopt_compression") == 0)
        return " (meshopt-compressed buffers: write the file without -c, e.g. gltfpack -noq)";
    if (strcmp(name, "EXT_mesh_gpu_instancing") == 0)
        return " (GPU instancing: each mesh would be drawn once instead of at every instance)";
    return "";
}

/* A glTF version "<major>.<minor>" (the schema's pattern ^[0-9]+\.[0-9]+$)
 * of length bytes at text; false if it is not one. */
static bool parse_version(const char *text, size_t length, uint32_t *major, uint32_t *minor)
{
    uint32_t part[2] = {0, 0};
    size_t k = 0;
    for (int p = 0; p < 2; p++) {
        const size_t start = k;
        while (k < length && text[k] >= '0' && text[k] <= '9') {
            if (part[p] > 100000000u)
                return false;
            part[p] = 10 * part[p] + (uint32_t)(text[k++] - '0');
        }
        if (k == start || (p == 0 && (k == length || text[k++] != '.')))
            return false;
    }
    if (k != length)
        return false;
    *major = part[0];
    *minor = part[1];
    return true;
}

/* glTF 2.0 §3.2 and the asset schema: asset.version is "<major>.<minor>",
 * and a reader refuses another major version, and a minVersion above the
 * 2.0 it reads (minVersion may not exceed version). A NULL text is absent;
 * *_typed false: given, but not as a string. */
static int check_version(struct importer *im, const char *version, size_t version_len,
                         bool version_typed, const char *min_version, size_t min_len,
                         bool min_typed)
{
    char shown[48];
    uint32_t major, minor, min_major, min_minor;
    if (!version_typed)
        return fail(im, TW_ERR_FORMAT, "asset.version: must be a string such as \"2.0\"");
    if (!version)
        return fail(im, TW_ERR_FORMAT, "asset.version: is missing");
    tw_log_escape_bytes(version, version_len, shown, sizeof(shown));
    if (!parse_version(version, version_len, &major, &minor))
        return fail(im, TW_ERR_FORMAT, "asset.version: \"%s\" is not <major>.<minor>", shown);
    if (major != 2)
        return fail(im, TW_ERR_FORMAT,
                    "asset.version: \"%s\" is glTF %u; this importer reads glTF 2.x", shown,
                    major);
    if (!min_typed)
        return fail(im, TW_ERR_FORMAT, "asset.minVersion: must be a string such as \"2.0\"");
    if (!min_version)
        return TW_OK;
    char min_shown[48];
    tw_log_escape_bytes(min_version, min_len, min_shown, sizeof(min_shown));
    if (!parse_version(min_version, min_len, &min_major, &min_minor))
        return fail(im, TW_ERR_FORMAT, "asset.minVersion: \"%s\" is not <major>.<minor>",
                    min_shown);
    if (min_major > major || (min_major == major && min_minor > minor))
        return fail(im, TW_ERR_FORMAT,
                    "asset.minVersion: \"%s\" is greater than asset.version \"%s\"", min_shown,
                    shown);
    if (min_major != 2 || min_minor > 0)
        return fail(im, TW_ERR_FORMAT,
                    "asset.minVersion: \"%s\": the document needs a glTF %u.%u reader; this "
                    "importer reads glTF 2.0",
                    min_shown, min_major, min_minor);
    return TW_OK;
}

/* The first required extension that the importer does not support, by name
 * (-1 if none). */
static int check_required(struct importer *im, const char *const *names, const size_t *lengths,
                          uint32_t count)
{
    for (uint32_t k = 0; k < count; k++) {
        if (!names[k] || (lengths && strlen(names[k]) != lengths[k]) ||
            !supported_extension(names[k])) {
            char shown[96];
            tw_log_escape(names[k] ? names[k] : "", shown, sizeof(shown));
            return fail(im, TW_ERR_FORMAT, "extensionsRequired[%u]: \"%s\" is not supported%s", k,
                        shown, names[k] ? extension_advice(names[k]) : "");
        }
    }
    return TW_OK;
}

static int import_document(struct importer *im, const uint8_t *data, size_t size,
                           struct tw_gltf_scene **out)
{
    struct tw_gltf_doc doc = {0};
    struct tw_gltf_scene *sc = NULL;
    struct tw_gltf_scan scan;
    int32_t *parent = NULL;
    int err;
    memset(&scan, 0, sizeof(scan));

    const uint8_t *text;
    size_t text_len;
    if ((err = find_json(im, data, &size, &text, &text_len)))
        goto out;
    if ((err = tw_gltf_scan(text, text_len, MAX_JSON_DEPTH, &scan))) {
        err = fail(im, err, "JSON: out of memory reading it");
        goto out;
    }
    if (scan.depth > MAX_JSON_DEPTH) {
        err = fail(im, TW_ERR_FORMAT, "JSON: nested %u levels deep, more than %d", scan.depth,
                   MAX_JSON_DEPTH);
        goto out;
    }
    if (scan.values > MAX_JSON_VALUES) {
        err = fail(im, TW_ERR_LIMIT, "JSON: %llu values, more than the limit of %d",
                   (unsigned long long)scan.values, MAX_JSON_VALUES);
        goto out;
    }
    {
        /* What tinygltf would refuse with a message that hides the cause
         * ("JSON string too short"): an empty text, a root that is not an
         * object. */
        size_t first = text_len >= 3 && memcmp(text, "\xef\xbb\xbf", 3) == 0 ? 3 : 0;
        while (first < text_len && (text[first] == ' ' || text[first] == '\t' ||
                                    text[first] == '\n' || text[first] == '\r'))
            first++;
        if (first == text_len) {
            err = fail(im, TW_ERR_FORMAT, "JSON: is empty%s",
                       text == data ? "" : " (the GLB's JSON chunk)");
            goto out;
        }
        if (text[first] != '{') {
            if (text[first] >= ' ' && text[first] < 0x7f)
                err = fail(im, TW_ERR_FORMAT, "JSON: the document is not a JSON object (it "
                                              "starts with '%c')",
                           text[first]);
            else
                err = fail(im, TW_ERR_FORMAT, "is neither a GLB (it does not start with "
                                              "\"glTF\") nor JSON text");
            goto out;
        }
    }
    /* The version first: a document for another glTF is refused as such,
     * not by what tinygltf trips on. */
    if (scan.valid && !scan.asset_found) {
        err = fail(im, TW_ERR_FORMAT, "asset: is missing or not an object (it gives the glTF "
                                      "version)");
        goto out;
    }
    if (scan.asset_found &&
        (err = check_version(im, scan.version.text, scan.version.length,
                             !scan.version_not_string, scan.min_version.text,
                             scan.min_version.length, !scan.min_version_not_string)))
        goto out;
    /* Only a GLB's buffer may omit its uri (the first: it is the BIN
     * chunk); tinygltf's message would say "File not found". */
    for (uint32_t k = 0; scan.valid && text == data && k < scan.buffer_uri_count; k++) {
        if (!scan.buffer_uris[k].text) {
            err = fail(im, TW_ERR_FORMAT, "buffers[%u]: has no uri (only a .glb's first buffer "
                                          "may omit it)",
                       k);
            goto out;
        }
    }
    {
        /* Before tinygltf: it would trip over what the extension changes
         * (a Draco primitive's accessors have no buffer view). */
        const char **names = malloc(sizeof(*names) * (scan.extensions_required_count + 1));
        size_t *lengths = malloc(sizeof(*lengths) * (scan.extensions_required_count + 1));
        if (!names || !lengths) {
            free(names);
            free(lengths);
            err = fail(im, TW_ERR_NOMEM, "JSON: out of memory");
            goto out;
        }
        for (uint32_t k = 0; k < scan.extensions_required_count; k++) {
            names[k] = scan.extensions_required[k].text;
            lengths[k] = scan.extensions_required[k].length;
        }
        err = check_required(im, names, lengths, scan.extensions_required_count);
        free(names);
        free(lengths);
        if (err)
            goto out;
    }
    {
        const uint64_t need = memory_estimate(&scan);
        uint64_t budget = MEMORY_BASE + MEMORY_PER_BYTE * (uint64_t)text_len;
        if (budget > MEMORY_MAX)
            budget = MEMORY_MAX;
        if (need > budget) {
            static const char *const names[TW_GLTF_KIND_COUNT] = {
                "accessors", "animations", "buffers", "bufferViews", "cameras", "images",
                "materials", "meshes", "nodes", "samplers", "scenes", "skins", "textures",
                "primitives"};
            int most = 0;
            for (int k = 1; k < TW_GLTF_KIND_COUNT; k++)
                if (scan.counts[k] * tw_gltf_shim_element_bytes((enum tw_gltf_kind)k) >
                    scan.counts[most] * tw_gltf_shim_element_bytes((enum tw_gltf_kind)most))
                    most = k;
            err = fail(im, TW_ERR_LIMIT,
                       "JSON: importing its %llu values (%llu %s, ...) would take about %llu MiB, "
                       "more than the %llu MiB allowed for %zu bytes of JSON",
                       (unsigned long long)scan.values, (unsigned long long)scan.counts[most],
                       names[most], (unsigned long long)(need >> 20),
                       (unsigned long long)(budget >> 20), text_len);
            goto out;
        }
    }
    im->scan = &scan;
    im->uri_used = calloc(scan.buffer_uri_count ? scan.buffer_uri_count : 1, 1);
    if (!im->uri_used) {
        err = fail(im, TW_ERR_NOMEM, "out of memory");
        goto out;
    }

    const struct tw_gltf_shim_io io = {read_external, im};
    char why[768];
    err = tw_gltf_shim_load(data, size, &io, scan.valid ? scan.counts : NULL, &doc, why,
                            sizeof(why));
    if (err) {
        if (im->io_error) {
            err = fail(im, im->io_error, "buffers: %s", im->io_msg);
        } else {
            char shown[768];
            err = fail(im, err, "%s",
                       why[0] ? tw_log_escape(why, shown, sizeof(shown)) : tw_error_to_str(err));
        }
        goto out;
    }
    im->doc = &doc;

    /* Checked on the scan already; again on what tinygltf read. */
    if ((err = check_version(im, doc.version && doc.version[0] ? doc.version : NULL,
                             doc.version ? strlen(doc.version) : 0, true,
                             doc.min_version && doc.min_version[0] ? doc.min_version : NULL,
                             doc.min_version ? strlen(doc.min_version) : 0, true)))
        goto out;
    if ((err = check_required(im, doc.extensions_required, NULL, doc.extensions_required_count)))
        goto out;
    parent = malloc(sizeof(*parent) * (doc.node_count ? doc.node_count : 1));
    sc = calloc(1, sizeof(*sc));
    im->image_of = calloc(doc.image_count ? doc.image_count : 1, sizeof(*im->image_of));
    im->facts = calloc(doc.accessor_count ? doc.accessor_count : 1, sizeof(*im->facts));
    im->material_textures =
        calloc(doc.material_count ? doc.material_count : 1, sizeof(*im->material_textures));
    if (!parent || !sc || !im->image_of || !im->facts || !im->material_textures) {
        err = fail(im, TW_ERR_NOMEM, "out of memory");
        goto out;
    }
    sc->source = copy_string(im->name);
    if (!sc->source) {
        err = fail(im, TW_ERR_NOMEM, "out of memory");
        goto out;
    }
    if ((err = check_buffer_views(im)) || (err = check_accessors(im)) ||
        (err = check_meshes(im)) || (err = check_mesh_data(im)) ||
        (err = check_nodes(im, parent)) ||
        (err = build_scene(im, parent, sc)))
        goto out;
    if (im->skipped_primitives == 1)
        warn(im, "%s is not drawn: only triangles, triangle strips and triangle fans are",
             im->skipped_first);
    else if (im->skipped_primitives > 1)
        warn(im, "%s and %u more point or line primitives are not drawn: only triangles, "
                 "triangle strips and triangle fans are",
             im->skipped_first, im->skipped_primitives - 1);
    *out = sc;
    sc = NULL;
out:
    tw_gltf_scene_destroy(sc);
    free(parent);
    if (im->texture_warnings > MAX_TEXTURE_WARNINGS)
        warn(im, "%u more warnings about textures and colours not shown",
             im->texture_warnings - MAX_TEXTURE_WARNINGS);
    image_cache_destroy(im->images);
    free(im->image_of);
    free(im->facts);
    im->facts = NULL;
    free(im->material_textures);
    free(im->uri_used);
    im->images = NULL;
    im->image_of = NULL;
    im->material_textures = NULL;
    im->uri_used = NULL;
    im->scan = NULL;
    tw_gltf_scan_finish(&scan);
    tw_gltf_shim_free(&doc);
    im->doc = NULL;
    return err;
}

/* The end of an import: logs the error, if any, and frees the import's own
 * shared state. */
static int import_end(struct importer *im, const struct tw_log *log, int err)
{
    if (im->own_shared)
        tw_gltf_shared_finish(im->shared);
    if (err)
        tw_log_printf(log, TW_LOG_ERROR, "%s: %s", im->shown,
                      im->msg[0] ? im->msg : tw_error_to_str(err));
    return err;
}

static void importer_init(struct importer *im, const char *name,
                          const struct tw_gltf_settings *settings, struct tw_gltf_shared *shared,
                          const struct tw_log *log)
{
    memset(im, 0, sizeof(*im));
    im->name = name;
    tw_log_escape(name, im->shown, sizeof(im->shown));
    im->dir_fd = -1;
    im->log = log;
    im->settings = resolve_settings(settings);
    im->own_shared = !shared;
    im->shared = shared ? shared : &im->own;
    if (!im->shared->max_bytes_read)
        im->shared->max_bytes_read = (shared ? 4 : 1) * im->settings.max_file_bytes;
    if (!im->shared->max_decoded_bytes)
        im->shared->max_decoded_bytes = TW_GLTF_MAX_DECODED_BYTES;
}

/* The start of an import from memory or a file: out checked and cleared,
 * im set up. */
static int import_begin(struct importer *im, const char *name,
                        const struct tw_gltf_settings *settings, struct tw_gltf_shared *shared,
                        const struct tw_log *log, struct tw_gltf_scene **out)
{
    if (!out) {
        tw_log_printf(log, TW_LOG_ERROR, "glTF import: out is NULL (caller's bug)");
        return TW_ERR_INVALID;
    }
    *out = NULL;
    importer_init(im, name, settings, shared, log);
    return TW_OK;
}

int tw_gltf_import_memory(const void *data, size_t size, const char *name, const char *base_dir,
                          const struct tw_gltf_settings *settings, const struct tw_log *log,
                          struct tw_gltf_scene **out)
{
    struct importer im;
    if (import_begin(&im, name ? name : "(memory)", settings, NULL, log, out))
        return TW_ERR_INVALID;
    if (!data && size)
        return import_end(&im, log, fail(&im, TW_ERR_INVALID, "no data (caller's bug)"));
    if (size > im.settings.max_file_bytes)
        return import_end(&im, log,
                          fail(&im, TW_ERR_LIMIT,
                               "is %zu bytes, more than the limit of %llu bytes", size,
                               (unsigned long long)im.settings.max_file_bytes));
    if (base_dir) {
        im.dir_fd = tw_confined_open_folder(base_dir);
        if (im.dir_fd < 0) {
            char shown[256];
            return import_end(&im, log,
                              fail(&im, TW_ERR_IO, "the folder of external files \"%s\": %s",
                                   tw_log_escape(base_dir, shown, sizeof(shown)),
                                   strerror(errno)));
        }
    }
    im.bytes_read = size;
    im.shared->bytes_read += size;
    static const uint8_t nothing = 0;
    const int err = import_document(&im, data ? data : &nothing, size, out);
    if (im.dir_fd >= 0)
        close(im.dir_fd);
    return import_end(&im, log, err);
}

int tw_gltf_import_fd(int fd, int dir_fd, const char *name,
                      const struct tw_gltf_settings *settings, struct tw_gltf_shared *shared,
                      const struct tw_log *log, struct tw_gltf_scene **out)
{
    struct importer im;
    if (import_begin(&im, name ? name : "(file)", settings, shared, log, out))
        return TW_ERR_INVALID;
    uint8_t *data = NULL;
    size_t size = 0;
    char why[512];
    int err = read_fd(&im, fd, &data, &size, why, sizeof(why));
    if (err)
        return import_end(&im, log, fail(&im, err, "%s", why));
    im.dir_fd = dir_fd;
    err = import_document(&im, data, size, out);
    free(data);
    return import_end(&im, log, err);
}

int tw_gltf_import(const char *path, const struct tw_gltf_settings *settings,
                   const struct tw_log *log, struct tw_gltf_scene **out)
{
    if (!out || !path) {
        tw_log_printf(log, TW_LOG_ERROR, "glTF import: %s is NULL (caller's bug)",
                      out ? "path" : "out");
        return TW_ERR_INVALID;
    }
    *out = NULL;
    char why[512];
    int fd = -1;
    int err = tw_confined_open_user(path, &fd, why, sizeof(why));
    if (err) {
        struct importer im;
        importer_init(&im, path, settings, NULL, log);
        return import_end(&im, log, fail(&im, err, "%s", why));
    }
    /* External files resolve beneath the document's own folder. */
    const int dir_fd = tw_confined_open_folder_of(path);
    err = tw_gltf_import_fd(fd, dir_fd, path, settings, NULL, log, out);
    close(fd);
    if (dir_fd >= 0)
        close(dir_fd);
    return err;
}

/* ---- tilesets -------------------------------------------------------------------- */

int tw_gltf_bind(const struct tw_gltf_scene *scene, struct tw_tileset *ts,
                 struct tw_gltf_binding *out)
{
    if (!scene || !ts || !out || ts->finished)
        return TW_ERR_INVALID;
    out->first_mesh = ts->mesh_count;
    out->first_material = ts->material_count;
    for (uint32_t k = 0; k < scene->material_count; k++) {
        int r = tw_tileset_add_material(ts, scene->materials[k].base_color);
        if (r < 0)
            return r;
    }
    for (uint32_t k = 0; k < scene->primitive_count; k++) {
        const struct tw_gltf_primitive *p = &scene->primitives[k];
        int r = tw_tileset_add_mesh(ts, p->positions, p->normals, p->vertex_count, p->indices,
                                    p->triangle_count);
        if (r < 0)
            return r;
    }
    return TW_OK;
}

int tw_gltf_place(const struct tw_gltf_scene *scene, const struct tw_gltf_binding *binding,
                  struct tw_tileset *ts, uint32_t proto, const float placement[12])
{
    static const float identity[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    if (!scene || !binding || !ts || ts->finished || proto >= ts->prototype_count ||
        binding->first_mesh + (uint64_t)scene->primitive_count > ts->mesh_count ||
        binding->first_material + (uint64_t)scene->material_count > ts->material_count)
        return TW_ERR_INVALID;
    if (!placement)
        placement = identity;
    double a[12];
    for (int k = 0; k < 12; k++)
        a[k] = placement[k];
    for (uint32_t k = 0; k < scene->instance_count; k++) {
        const struct tw_gltf_instance *in = &scene->instances[k];
        double b[12], c[12];
        float t[12];
        for (int e = 0; e < 12; e++)
            b[e] = in->transform[e];
        compose(a, b, c);
        for (int e = 0; e < 12; e++)
            t[e] = (float)c[e];
        const struct tw_gltf_mesh *gm = &scene->meshes[in->mesh];
        for (uint32_t p = 0; p < gm->primitive_count; p++) {
            const uint32_t prim = gm->first_primitive + p;
            const int r = tw_tileset_add_instance(ts, proto, binding->first_mesh + prim,
                                                  binding->first_material +
                                                      scene->primitives[prim].material,
                                                  t);
            if (r < 0)
                return r;
        }
    }
    return TW_OK;
}

void tw_gltf_placement(const float position[3], float yaw_degrees, float scale, float out[12])
{
    const double yaw = (double)yaw_degrees * 3.14159265358979323846 / 180.0;
    const double c = cos(yaw), s = sin(yaw);
    /* R_y(yaw): +z turns towards +x. */
    const double r[9] = {c, 0, s, 0, 1, 0, -s, 0, c};
    for (int row = 0; row < 3; row++) {
        for (int col = 0; col < 3; col++)
            out[4 * row + col] = (float)(r[3 * row + col] * scale);
        out[4 * row + 3] = position ? position[row] : 0.0f;
    }
}
