/* glTF import (tilesets.h), its entry points and the document as a whole:
 * tinygltf parses (gltf-shim.cpp), the importer's files (gltf-private.h)
 * check everything themselves and convert.
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

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "tilesets/confined-path.h"
#include "tilesets/gltf-private.h"

#define DEFAULT_MAX_FILE_BYTES (256ull << 20)
#define DEFAULT_MAX_TRIANGLES 10000000ull
/* JSON nesting deeper than this is refused before tinygltf sees it: its
 * value parser recurses once per level. */
#define MAX_JSON_DEPTH 256
/* tinygltf holds the whole JSON tree, at tens to hundreds of bytes per
 * value: bound the count so that a file within max_file_bytes cannot make it
 * allocate gigabytes. Real documents keep their bulk in buffers. */
#define MAX_JSON_VALUES (4 << 20)
/* Texture warnings shown per import; the rest are counted in one line. */
#define MAX_TEXTURE_WARNINGS 8

void tw_gltf_default_settings(struct tw_gltf_settings *s)
{
    if (!s)
        return;
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

/* ---- the import context and its messages --------------------------------------- */

int tw_gltf_fail(struct tw_gltf_importer *im, int err, const char *fmt, ...)
{
    if (!im->msg[0]) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(im->msg, sizeof(im->msg), fmt, ap);
        va_end(ap);
    }
    return err;
}

static void warn(struct tw_gltf_importer *im, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static void warn(struct tw_gltf_importer *im, const char *fmt, ...)
{
    char text[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof(text), fmt, ap);
    va_end(ap);
    tw_log_printf(im->log, TW_LOG_WARN, "%s: %s", im->shown, text);
}

/* "4.3 GiB", "17 MiB", "300 KiB", "12 bytes". */
const char *tw_gltf_byte_size(uint64_t n, char *out, size_t size)
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

/* A texture that cannot be used costs a warning, never the import; past
 * MAX_TEXTURE_WARNINGS of them they are only counted. */
void tw_gltf_warn_texture(struct tw_gltf_importer *im, const char *fmt, ...)
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

/* Bytes that importing a document with this JSON will hold, from the scan
 * alone: nlohmann::json's tree (measured: about 24 bytes per value, 64 more
 * per object, 96 per member, 48 per string plus its text), tinygltf's and
 * the shim's objects (their sizes, from the shim), tinygltf's copies of the
 * extras and extensions as tinygltf::Value trees, string copies, and what
 * the importer keeps per node and per primitive. An overestimate: the tree is
 * freed before the shim copies anything. */
static uint64_t memory_estimate(const struct tw_gltf_scan *s)
{
    uint64_t bytes = 32 * s->values + 64 * s->objects + 96 * s->members + 48 * s->strings +
                     4 * s->string_bytes + 256 * s->extension_values;
    for (int k = 0; k < TW_GLTF_KIND_COUNT; k++)
        bytes += s->counts[k] * tw_gltf_shim_element_bytes((enum tw_gltf_kind)k);
    /* tw_gltf_build_scene(): parent, stack, world transform, instance, node per node. */
    bytes += s->counts[TW_GLTF_NODES] * (4 + 4 + 96 + sizeof(struct tw_gltf_instance) + 4 + 1);
    bytes += s->counts[TW_GLTF_MATERIALS] *
             (sizeof(struct tw_material) + sizeof(struct tw_gltf_material_texture));
    bytes +=
        s->counts[TW_GLTF_IMAGES] * (sizeof(struct tw_gltf_decoded_image) + 2 * sizeof(void *));
    bytes += s->counts[TW_GLTF_ACCESSORS] * sizeof(struct tw_gltf_accessor_facts);
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
static int check_version(struct tw_gltf_importer *im, const char *version, size_t version_len,
                         bool version_typed, const char *min_version, size_t min_len,
                         bool min_typed)
{
    char shown[48];
    uint32_t major, minor, min_major, min_minor;
    if (!version_typed)
        return tw_gltf_fail(im, TW_ERR_FORMAT, "asset.version: must be a string such as \"2.0\"");
    if (!version)
        return tw_gltf_fail(im, TW_ERR_FORMAT, "asset.version: is missing");
    tw_log_escape_bytes(version, version_len, shown, sizeof(shown));
    if (!parse_version(version, version_len, &major, &minor))
        return tw_gltf_fail(im, TW_ERR_FORMAT, "asset.version: \"%s\" is not <major>.<minor>",
                            shown);
    if (major != 2)
        return tw_gltf_fail(im, TW_ERR_FORMAT,
                            "asset.version: \"%s\" is glTF %u; this importer reads glTF 2.x", shown,
                            major);
    if (!min_typed)
        return tw_gltf_fail(im, TW_ERR_FORMAT,
                            "asset.minVersion: must be a string such as \"2.0\"");
    if (!min_version)
        return TW_OK;
    char min_shown[48];
    tw_log_escape_bytes(min_version, min_len, min_shown, sizeof(min_shown));
    if (!parse_version(min_version, min_len, &min_major, &min_minor))
        return tw_gltf_fail(im, TW_ERR_FORMAT, "asset.minVersion: \"%s\" is not <major>.<minor>",
                            min_shown);
    if (min_major > major || (min_major == major && min_minor > minor))
        return tw_gltf_fail(im, TW_ERR_FORMAT,
                            "asset.minVersion: \"%s\" is greater than asset.version \"%s\"",
                            min_shown, shown);
    if (min_major != 2 || min_minor > 0)
        return tw_gltf_fail(
            im, TW_ERR_FORMAT,
            "asset.minVersion: \"%s\": the document needs a glTF %u.%u reader; this "
            "importer reads glTF 2.0",
            min_shown, min_major, min_minor);
    return TW_OK;
}

/* The first required extension that the importer does not support, by name
 * (-1 if none). */
static int check_required(struct tw_gltf_importer *im, const char *const *names,
                          const size_t *lengths, uint32_t count)
{
    for (uint32_t k = 0; k < count; k++) {
        if (!names[k] || (lengths && strlen(names[k]) != lengths[k]) ||
            !supported_extension(names[k])) {
            char shown[96];
            tw_log_escape(names[k] ? names[k] : "", shown, sizeof(shown));
            return tw_gltf_fail(im, TW_ERR_FORMAT,
                                "extensionsRequired[%u]: \"%s\" is not supported%s", k, shown,
                                names[k] ? extension_advice(names[k]) : "");
        }
    }
    return TW_OK;
}

static int import_document(struct tw_gltf_importer *im, const uint8_t *data, size_t size,
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
    if ((err = tw_gltf_find_json(im, data, &size, &text, &text_len)))
        goto out;
    if ((err = tw_gltf_scan(text, text_len, MAX_JSON_DEPTH, &scan))) {
        err = tw_gltf_fail(im, err, "JSON: out of memory reading it");
        goto out;
    }
    if (scan.depth > MAX_JSON_DEPTH) {
        err = tw_gltf_fail(im, TW_ERR_FORMAT, "JSON: nested %u levels deep, more than %d",
                           scan.depth, MAX_JSON_DEPTH);
        goto out;
    }
    if (scan.values > MAX_JSON_VALUES) {
        err = tw_gltf_fail(im, TW_ERR_LIMIT, "JSON: %llu values, more than the limit of %d",
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
            err = tw_gltf_fail(im, TW_ERR_FORMAT, "JSON: is empty%s",
                               text == data ? "" : " (the GLB's JSON chunk)");
            goto out;
        }
        if (text[first] != '{') {
            if (text[first] >= ' ' && text[first] < 0x7f)
                err = tw_gltf_fail(im, TW_ERR_FORMAT,
                                   "JSON: the document is not a JSON object (it "
                                   "starts with '%c')",
                                   text[first]);
            else
                err = tw_gltf_fail(im, TW_ERR_FORMAT,
                                   "is neither a GLB (it does not start with "
                                   "\"glTF\") nor JSON text");
            goto out;
        }
    }
    /* The version first: a document for another glTF is refused as such,
     * not by what tinygltf trips on. */
    if (scan.valid && !scan.asset_found) {
        err = tw_gltf_fail(im, TW_ERR_FORMAT,
                           "asset: is missing or not an object (it gives the glTF "
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
            err = tw_gltf_fail(im, TW_ERR_FORMAT,
                               "buffers[%u]: has no uri (only a .glb's first buffer "
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
            err = tw_gltf_fail(im, TW_ERR_NOMEM, "JSON: out of memory");
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
        uint64_t budget = TW_GLTF_MEMORY_BASE + TW_GLTF_MEMORY_PER_BYTE * (uint64_t)text_len;
        if (budget > TW_GLTF_MEMORY_MAX)
            budget = TW_GLTF_MEMORY_MAX;
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
            err = tw_gltf_fail(
                im, TW_ERR_LIMIT,
                "JSON: importing its %llu values (%llu %s, ...) would take about %llu MiB, "
                "more than the %llu MiB allowed for %zu bytes of JSON",
                (unsigned long long)scan.values, (unsigned long long)scan.counts[most], names[most],
                (unsigned long long)(need >> 20), (unsigned long long)(budget >> 20), text_len);
            goto out;
        }
    }
    im->scan = &scan;
    im->uri_used = calloc(scan.buffer_uri_count ? scan.buffer_uri_count : 1, 1);
    if (!im->uri_used) {
        err = tw_gltf_fail(im, TW_ERR_NOMEM, "out of memory");
        goto out;
    }

    const struct tw_gltf_shim_io io = {tw_gltf_read_external, im};
    char why[768];
    err = tw_gltf_shim_load(data, size, &io, scan.valid ? scan.counts : NULL, &doc, why,
                            sizeof(why));
    if (err) {
        if (im->io_error) {
            err = tw_gltf_fail(im, im->io_error, "buffers: %s", im->io_msg);
        } else {
            char shown[768];
            err = tw_gltf_fail(im, err, "%s",
                               why[0] ? tw_log_escape(why, shown, sizeof(shown))
                                      : tw_error_to_str(err));
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
        err = tw_gltf_fail(im, TW_ERR_NOMEM, "out of memory");
        goto out;
    }
    sc->source = copy_string(im->name);
    if (!sc->source) {
        err = tw_gltf_fail(im, TW_ERR_NOMEM, "out of memory");
        goto out;
    }
    if ((err = tw_gltf_check_buffer_views(im)) || (err = tw_gltf_check_accessors(im)) ||
        (err = tw_gltf_check_meshes(im)) || (err = tw_gltf_check_mesh_data(im)) ||
        (err = tw_gltf_check_nodes(im, parent)) || (err = tw_gltf_build_scene(im, parent, sc)))
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
    tw_gltf_image_cache_destroy(im->images);
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
static int import_end(struct tw_gltf_importer *im, const struct tw_log *log, int err)
{
    if (im->own_shared)
        tw_gltf_shared_finish(im->shared);
    if (err)
        tw_log_printf(log, TW_LOG_ERROR, "%s: %s", im->shown,
                      im->msg[0] ? im->msg : tw_error_to_str(err));
    return err;
}

static void importer_init(struct tw_gltf_importer *im, const char *name,
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
static int import_begin(struct tw_gltf_importer *im, const char *name,
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
    struct tw_gltf_importer im;
    if (import_begin(&im, name ? name : "(memory)", settings, NULL, log, out))
        return TW_ERR_INVALID;
    if (!data && size)
        return import_end(&im, log, tw_gltf_fail(&im, TW_ERR_INVALID, "no data (caller's bug)"));
    if (size > im.settings.max_file_bytes)
        return import_end(&im, log,
                          tw_gltf_fail(&im, TW_ERR_LIMIT,
                                       "is %zu bytes, more than the limit of %llu bytes", size,
                                       (unsigned long long)im.settings.max_file_bytes));
    if (base_dir) {
        im.dir_fd = tw_confined_open_folder(base_dir);
        if (im.dir_fd < 0) {
            char shown[256];
            return import_end(
                &im, log,
                tw_gltf_fail(&im, TW_ERR_IO, "the folder of external files \"%s\": %s",
                             tw_log_escape(base_dir, shown, sizeof(shown)), strerror(errno)));
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
    struct tw_gltf_importer im;
    if (import_begin(&im, name ? name : "(file)", settings, shared, log, out))
        return TW_ERR_INVALID;
    uint8_t *data = NULL;
    size_t size = 0;
    char why[512];
    int err = tw_gltf_read_fd(&im, fd, &data, &size, why, sizeof(why));
    if (err)
        return import_end(&im, log, tw_gltf_fail(&im, err, "%s", why));
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
        struct tw_gltf_importer im;
        importer_init(&im, path, settings, NULL, log);
        return import_end(&im, log, tw_gltf_fail(&im, err, "%s", why));
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
        tw_gltf_compose(a, b, c);
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
