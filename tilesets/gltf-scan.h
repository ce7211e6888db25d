/*
 * A first pass over a glTF document's JSON text, before tinygltf parses it
 * (private to tilesets/, used by gltf-import.c and gltf-io.c). It allocates nothing but what it
 * returns, recurses at most max_depth levels, and gives what the importer
 * must know before it lets tinygltf loose:
 *
 *   - how deep the text nests and how many JSON values, objects, members and
 *     string bytes it holds, and how many elements each top-level array
 *     ("nodes", "materials", ...) has: tinygltf's memory is a sum of those,
 *     so the importer can refuse a document that would take more than its
 *     budget, and reserve exact room for the rest;
 *   - the raw "uri" of every buffer, as written (tinygltf hands the reader a
 *     URL-decoded copy that turned '+' into a space);
 *   - the names in "extensionsRequired", so that an unsupported one is
 *     reported by name instead of as whatever tinygltf trips on first;
 *   - "asset": its "version" and "minVersion", so that a document for
 *     another glTF version is refused as such before it is parsed.
 *
 * For a text that is not JSON the scan stops where the text stops being JSON
 * (valid is false) with what it counted so far; tinygltf then reports the
 * syntax error. Duplicate keys keep their last value, as nlohmann::json does.
 */
#ifndef TW_TILESETS_GLTF_SCAN_H
#define TW_TILESETS_GLTF_SCAN_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* The top-level arrays whose elements become tinygltf objects. */
enum tw_gltf_kind {
    TW_GLTF_ACCESSORS = 0,
    TW_GLTF_ANIMATIONS,
    TW_GLTF_BUFFERS,
    TW_GLTF_BUFFER_VIEWS,
    TW_GLTF_CAMERAS,
    TW_GLTF_IMAGES,
    TW_GLTF_MATERIALS,
    TW_GLTF_MESHES,
    TW_GLTF_NODES,
    TW_GLTF_SAMPLERS,
    TW_GLTF_SCENES,
    TW_GLTF_SKINS,
    TW_GLTF_TEXTURES,
    TW_GLTF_PRIMITIVES,         /* meshes[*].primitives[*] */
    TW_GLTF_KIND_COUNT
};

/* A string from the document, JSON escapes decoded. */
struct tw_gltf_scan_string {
    char *text;                 /* NUL-terminated, malloc()ed; NULL: absent */
    size_t length;              /* bytes before the terminator (a \u0000 shortens nothing) */
};

struct tw_gltf_scan {
    bool valid;                 /* the whole text is one JSON object */
    uint32_t depth;             /* deepest nesting (> max_depth: the scan stopped there) */
    uint64_t values;            /* every value: scalars, strings, arrays, objects */
    uint64_t objects;
    uint64_t arrays;
    uint64_t members;           /* key: value pairs */
    uint64_t strings;           /* string values and keys */
    uint64_t string_bytes;      /* their raw length */
    uint64_t extension_values;  /* values inside "extras" and "extensions" (tinygltf keeps a
                                   copy of each as a tinygltf::Value) */
    uint64_t counts[TW_GLTF_KIND_COUNT];
    /* buffers[k].uri, one per element of "buffers" (text NULL: no uri). */
    struct tw_gltf_scan_string *buffer_uris;
    uint32_t buffer_uri_count;
    struct tw_gltf_scan_string *extensions_required;
    uint32_t extensions_required_count;
    /* asset.version and asset.minVersion (text NULL: absent, or not a
     * string when the matching *_not_string is set). */
    bool asset_found;           /* the document has an "asset" object */
    struct tw_gltf_scan_string version, min_version;
    bool version_not_string, min_version_not_string;
};

/* Scans text[0, size) (a .gltf, or a .glb's JSON chunk). Returns 0, or
 * TW_ERR_NOMEM; *out is then to be freed with tw_gltf_scan_finish() in
 * either case. */
int tw_gltf_scan(const uint8_t *text, size_t size, uint32_t max_depth, struct tw_gltf_scan *out);

void tw_gltf_scan_finish(struct tw_gltf_scan *s);

/* The value of the hexadecimal digit c (either case), or -1. */
int tw_gltf_hex_digit(int c);

#endif
