/* The first pass over a glTF document's JSON (gltf-scan.h): a strict JSON
 * reader (RFC 8259) that counts and keeps a few strings, without building a
 * tree. */
#include "tilesets/gltf-scan.h"

#include <stdlib.h>
#include <string.h>

#include "tileworld/tiles.h"

/* Where a value lies, as far as the scan cares. */
enum context {
    IN_OTHER = 0,
    IN_ROOT,            /* the document object */
    IN_KIND_ARRAY,      /* a top-level array of objects of one kind */
    IN_BUFFERS,         /* "buffers" */
    IN_BUFFER,          /* one of its elements */
    IN_REQUIRED,        /* "extensionsRequired" */
    IN_MESHES,          /* "meshes" */
    IN_MESH,            /* one of its elements */
    IN_PRIMITIVES,      /* meshes[*].primitives */
    IN_ASSET,           /* "asset" */
};

static const char *const kind_keys[TW_GLTF_KIND_COUNT] = {
    "accessors", "animations", "buffers", "bufferViews", "cameras", "images", "materials",
    "meshes", "nodes", "samplers", "scenes", "skins", "textures", NULL,
};

struct scanner {
    const uint8_t *s;
    size_t n, pos;
    uint32_t max_depth;
    struct tw_gltf_scan *out;
    bool failed;        /* not JSON, or too deep: stop */
    int err;            /* TW_ERR_NOMEM */
};

static void skip_space(struct scanner *sc)
{
    while (sc->pos < sc->n && (sc->s[sc->pos] == ' ' || sc->s[sc->pos] == '\t' ||
                               sc->s[sc->pos] == '\n' || sc->s[sc->pos] == '\r'))
        sc->pos++;
}

static bool fail(struct scanner *sc)
{
    sc->failed = true;
    return false;
}

int tw_gltf_hex_digit(int c)
{
    if (c >= '0' && c <= '9')
        return c - '0';
    if (c >= 'a' && c <= 'f')
        return c - 'a' + 10;
    if (c >= 'A' && c <= 'F')
        return c - 'A' + 10;
    return -1;
}

static bool read_hex4(struct scanner *sc, uint32_t *v)
{
    if (sc->n - sc->pos < 4)
        return false;
    *v = 0;
    for (int k = 0; k < 4; k++) {
        const int h = tw_gltf_hex_digit(sc->s[sc->pos + (size_t)k]);
        if (h < 0)
            return false;
        *v = *v << 4 | (uint32_t)h;
    }
    sc->pos += 4;
    return true;
}

static size_t put_utf8(uint32_t cp, char *out)
{
    if (cp < 0x80) {
        out[0] = (char)cp;
        return 1;
    }
    if (cp < 0x800) {
        out[0] = (char)(0xc0 | cp >> 6);
        out[1] = (char)(0x80 | (cp & 0x3f));
        return 2;
    }
    if (cp < 0x10000) {
        out[0] = (char)(0xe0 | cp >> 12);
        out[1] = (char)(0x80 | (cp >> 6 & 0x3f));
        out[2] = (char)(0x80 | (cp & 0x3f));
        return 3;
    }
    out[0] = (char)(0xf0 | cp >> 18);
    out[1] = (char)(0x80 | (cp >> 12 & 0x3f));
    out[2] = (char)(0x80 | (cp >> 6 & 0x3f));
    out[3] = (char)(0x80 | (cp & 0x3f));
    return 4;
}

/* A string at pos (the opening quote). keep non-NULL: its decoded text
 * replaces *keep. */
static bool scan_string(struct scanner *sc, struct tw_gltf_scan_string *keep)
{
    const size_t start = ++sc->pos;
    char *text = NULL;
    size_t len = 0;
    if (keep) {
        /* Decoded text is never longer than the raw one. */
        size_t end = start;
        while (end < sc->n && sc->s[end] != '"')
            end += sc->s[end] == '\\' ? 2 : 1;
        text = malloc((end < sc->n ? end : sc->n) - start + 1);
        if (!text) {
            sc->err = TW_ERR_NOMEM;
            return fail(sc);
        }
    }
    for (;;) {
        if (sc->pos >= sc->n)
            goto bad;
        const uint8_t c = sc->s[sc->pos];
        if (c == '"')
            break;
        if (c < 0x20)
            goto bad;
        if (c != '\\') {
            if (text)
                text[len++] = (char)c;
            sc->pos++;
            continue;
        }
        if (++sc->pos >= sc->n)
            goto bad;
        const uint8_t e = sc->s[sc->pos++];
        char plain = 0;
        switch (e) {
        case '"': plain = '"'; break;
        case '\\': plain = '\\'; break;
        case '/': plain = '/'; break;
        case 'b': plain = '\b'; break;
        case 'f': plain = '\f'; break;
        case 'n': plain = '\n'; break;
        case 'r': plain = '\r'; break;
        case 't': plain = '\t'; break;
        case 'u': {
            uint32_t cp;
            if (!read_hex4(sc, &cp))
                goto bad;
            if (cp >= 0xdc00 && cp <= 0xdfff)
                goto bad;
            if (cp >= 0xd800 && cp <= 0xdbff) {
                uint32_t low;
                if (sc->n - sc->pos < 2 || sc->s[sc->pos] != '\\' || sc->s[sc->pos + 1] != 'u')
                    goto bad;
                sc->pos += 2;
                if (!read_hex4(sc, &low) || low < 0xdc00 || low > 0xdfff)
                    goto bad;
                cp = 0x10000 + ((cp - 0xd800) << 10) + (low - 0xdc00);
            }
            if (text)
                len += put_utf8(cp, text + len);
            continue;
        }
        default:
            goto bad;
        }
        if (text)
            text[len++] = plain;
    }
    sc->out->strings++;
    sc->out->string_bytes += sc->pos - start;
    sc->pos++;
    if (keep) {
        text[len] = '\0';
        free(keep->text);
        keep->text = text;
        keep->length = len;
    }
    return true;
bad:
    free(text);
    return fail(sc);
}

static bool scan_number(struct scanner *sc)
{
    const uint8_t *s = sc->s;
    size_t p = sc->pos;
    if (p < sc->n && s[p] == '-')
        p++;
    if (p >= sc->n)
        return fail(sc);
    if (s[p] == '0') {
        p++;
    } else if (s[p] >= '1' && s[p] <= '9') {
        while (p < sc->n && s[p] >= '0' && s[p] <= '9')
            p++;
    } else {
        return fail(sc);
    }
    if (p < sc->n && s[p] == '.') {
        if (++p >= sc->n || s[p] < '0' || s[p] > '9')
            return fail(sc);
        while (p < sc->n && s[p] >= '0' && s[p] <= '9')
            p++;
    }
    if (p < sc->n && (s[p] == 'e' || s[p] == 'E')) {
        p++;
        if (p < sc->n && (s[p] == '+' || s[p] == '-'))
            p++;
        if (p >= sc->n || s[p] < '0' || s[p] > '9')
            return fail(sc);
        while (p < sc->n && s[p] >= '0' && s[p] <= '9')
            p++;
    }
    sc->pos = p;
    return true;
}

static bool scan_literal(struct scanner *sc, const char *word)
{
    const size_t len = strlen(word);
    if (sc->n - sc->pos < len || memcmp(sc->s + sc->pos, word, len) != 0)
        return fail(sc);
    sc->pos += len;
    return true;
}

static bool key_is(const struct tw_gltf_scan_string *key, const char *name)
{
    return key->text && strcmp(key->text, name) == 0;
}

static void free_strings(struct tw_gltf_scan_string **list, uint32_t *count)
{
    for (uint32_t k = 0; *list && k < *count; k++)
        free((*list)[k].text);
    free(*list);
    *list = NULL;
    *count = 0;
}

/* Appends an absent string to *list; NULL when out of memory. */
static struct tw_gltf_scan_string *append_string(struct scanner *sc,
                                                 struct tw_gltf_scan_string **list,
                                                 uint32_t *count)
{
    if (*count == UINT32_MAX) {
        fail(sc);
        return NULL;
    }
    /* Grows by doubling: capacity is the next power of two. */
    const uint32_t n = *count;
    if ((n & (n - 1)) == 0) {
        const size_t cap = n ? 2 * (size_t)n : 4;
        struct tw_gltf_scan_string *grown = realloc(*list, sizeof(*grown) * cap);
        if (!grown) {
            sc->err = TW_ERR_NOMEM;
            fail(sc);
            return NULL;
        }
        *list = grown;
    }
    struct tw_gltf_scan_string *s = &(*list)[(*count)++];
    s->text = NULL;
    s->length = 0;
    return s;
}

static bool scan_value(struct scanner *sc, uint32_t depth, enum context ctx, int kind,
                       bool in_extension);

static void clear_asset(struct tw_gltf_scan *out)
{
    free(out->version.text);
    free(out->min_version.text);
    out->version.text = out->min_version.text = NULL;
    out->version.length = out->min_version.length = 0;
    out->asset_found = out->version_not_string = out->min_version_not_string = false;
}

/* The value of member key of an object in context ctx. */
static bool scan_member_value(struct scanner *sc, uint32_t depth, enum context ctx,
                              const struct tw_gltf_scan_string *key, bool in_extension,
                              struct tw_gltf_scan_string *uri)
{
    if (key_is(key, "extras") || key_is(key, "extensions"))
        return scan_value(sc, depth, IN_OTHER, -1, true);
    if (ctx == IN_ROOT) {
        if (key_is(key, "extensionsRequired")) {
            free_strings(&sc->out->extensions_required, &sc->out->extensions_required_count);
            return scan_value(sc, depth, IN_REQUIRED, -1, in_extension);
        }
        if (key_is(key, "asset")) {
            /* A repeated "asset" replaces the earlier one. */
            clear_asset(sc->out);
            sc->out->asset_found = sc->pos < sc->n && sc->s[sc->pos] == '{';
            return scan_value(sc, depth, IN_ASSET, -1, in_extension);
        }
        for (int k = 0; kind_keys[k]; k++) {
            if (!key_is(key, kind_keys[k]))
                continue;
            /* A repeated key replaces the earlier value (nlohmann::json). */
            sc->out->counts[k] = 0;
            if (k == TW_GLTF_BUFFERS) {
                free_strings(&sc->out->buffer_uris, &sc->out->buffer_uri_count);
                return scan_value(sc, depth, IN_BUFFERS, k, in_extension);
            }
            if (k == TW_GLTF_MESHES) {
                sc->out->counts[TW_GLTF_PRIMITIVES] = 0;
                return scan_value(sc, depth, IN_MESHES, k, in_extension);
            }
            return scan_value(sc, depth, IN_KIND_ARRAY, k, in_extension);
        }
    } else if (ctx == IN_BUFFER && key_is(key, "uri") && uri) {
        if (sc->pos < sc->n && sc->s[sc->pos] == '"') {
            sc->out->values++;
            return scan_string(sc, uri);
        }
    } else if (ctx == IN_ASSET && (key_is(key, "version") || key_is(key, "minVersion"))) {
        const bool min = key_is(key, "minVersion");
        struct tw_gltf_scan_string *keep = min ? &sc->out->min_version : &sc->out->version;
        bool *not_string = min ? &sc->out->min_version_not_string : &sc->out->version_not_string;
        free(keep->text);
        keep->text = NULL;
        keep->length = 0;
        *not_string = !(sc->pos < sc->n && sc->s[sc->pos] == '"');
        if (!*not_string) {
            sc->out->values++;
            return scan_string(sc, keep);
        }
    } else if (ctx == IN_MESH && key_is(key, "primitives")) {
        return scan_value(sc, depth, IN_PRIMITIVES, TW_GLTF_PRIMITIVES, in_extension);
    }
    return scan_value(sc, depth, IN_OTHER, -1, in_extension);
}

/* After a member or an element: skips a ',' (more follow: 1) or the closing
 * character close (that was the last: 0); anything else fails the scan (-1). */
static int after_item(struct scanner *sc, char close)
{
    skip_space(sc);
    if (sc->pos < sc->n && sc->s[sc->pos] == ',') {
        sc->pos++;
        return 1;
    }
    if (sc->pos < sc->n && sc->s[sc->pos] == close) {
        sc->pos++;
        return 0;
    }
    fail(sc);
    return -1;
}

static bool scan_object(struct scanner *sc, uint32_t depth, enum context ctx, bool in_extension)
{
    sc->out->objects++;
    sc->pos++;
    /* A buffer's uri: the last one given wins. */
    struct tw_gltf_scan_string *uri = NULL;
    if (ctx == IN_BUFFER) {
        uri = append_string(sc, &sc->out->buffer_uris, &sc->out->buffer_uri_count);
        if (!uri)
            return false;
    }
    skip_space(sc);
    if (sc->pos < sc->n && sc->s[sc->pos] == '}') {
        sc->pos++;
        return true;
    }
    struct tw_gltf_scan_string key = {NULL, 0};
    bool ok = false;
    for (;;) {
        skip_space(sc);
        if (sc->pos >= sc->n || sc->s[sc->pos] != '"') {
            fail(sc);
            break;
        }
        /* Keys are kept only where the scan looks at them. */
        const bool want_key = ctx == IN_ROOT || ctx == IN_BUFFER || ctx == IN_MESH ||
                              ctx == IN_ASSET || !in_extension;
        if (!scan_string(sc, want_key ? &key : NULL))
            break;
        if (!want_key) {
            free(key.text);
            key.text = NULL;
        }
        sc->out->members++;
        skip_space(sc);
        if (sc->pos >= sc->n || sc->s[sc->pos] != ':') {
            fail(sc);
            break;
        }
        sc->pos++;
        skip_space(sc);
        if (!scan_member_value(sc, depth, ctx, &key, in_extension, uri))
            break;
        const int more = after_item(sc, '}');
        if (more > 0)
            continue;
        ok = more == 0;
        break;
    }
    free(key.text);
    return ok;
}

static bool scan_array(struct scanner *sc, uint32_t depth, enum context ctx, int kind,
                       bool in_extension)
{
    sc->out->arrays++;
    sc->pos++;
    skip_space(sc);
    if (sc->pos < sc->n && sc->s[sc->pos] == ']') {
        sc->pos++;
        return true;
    }
    enum context element = IN_OTHER;
    if (ctx == IN_BUFFERS)
        element = IN_BUFFER;
    else if (ctx == IN_MESHES)
        element = IN_MESH;
    for (;;) {
        skip_space(sc);
        if (kind >= 0)
            sc->out->counts[kind]++;
        if (ctx == IN_BUFFERS && !(sc->pos < sc->n && sc->s[sc->pos] == '{')) {
            /* Not an object: a buffer without a uri (tinygltf refuses it). */
            if (!append_string(sc, &sc->out->buffer_uris, &sc->out->buffer_uri_count))
                return false;
        }
        if (ctx == IN_REQUIRED && sc->pos < sc->n && sc->s[sc->pos] == '"') {
            struct tw_gltf_scan_string *name = append_string(
                sc, &sc->out->extensions_required, &sc->out->extensions_required_count);
            if (!name)
                return false;
            sc->out->values++;
            if (!scan_string(sc, name))
                return false;
        } else if (!scan_value(sc, depth, element, -1, in_extension)) {
            return false;
        }
        const int more = after_item(sc, ']');
        if (more > 0)
            continue;
        return more == 0;
    }
}

static bool scan_value(struct scanner *sc, uint32_t depth, enum context ctx, int kind,
                       bool in_extension)
{
    skip_space(sc);
    if (sc->pos >= sc->n)
        return fail(sc);
    sc->out->values++;
    if (in_extension)
        sc->out->extension_values++;
    const uint8_t c = sc->s[sc->pos];
    if (c == '{' || c == '[') {
        if (depth + 1 > sc->out->depth)
            sc->out->depth = depth + 1;
        if (depth + 1 > sc->max_depth)
            return fail(sc);
        if (c == '{')
            return scan_object(sc, depth + 1, ctx, in_extension);
        return scan_array(sc, depth + 1, ctx, kind, in_extension);
    }
    if (c == '"')
        return scan_string(sc, NULL);
    if (c == 't')
        return scan_literal(sc, "true");
    if (c == 'f')
        return scan_literal(sc, "false");
    if (c == 'n')
        return scan_literal(sc, "null");
    return scan_number(sc);
}

int tw_gltf_scan(const uint8_t *text, size_t size, uint32_t max_depth, struct tw_gltf_scan *out)
{
    memset(out, 0, sizeof(*out));
    struct scanner sc = {text, text ? size : 0, 0, max_depth, out, false, TW_OK};
    /* nlohmann::json skips a UTF-8 byte order mark. */
    if (sc.n >= 3 && memcmp(text, "\xef\xbb\xbf", 3) == 0)
        sc.pos = 3;
    skip_space(&sc);
    if (sc.pos < sc.n && text[sc.pos] == '{' && scan_value(&sc, 0, IN_ROOT, -1, false)) {
        skip_space(&sc);
        out->valid = sc.pos == sc.n;
    }
    return sc.err;
}

void tw_gltf_scan_finish(struct tw_gltf_scan *s)
{
    if (!s)
        return;
    free_strings(&s->buffer_uris, &s->buffer_uri_count);
    free_strings(&s->extensions_required, &s->extensions_required_count);
    clear_asset(s);
}
