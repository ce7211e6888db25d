/* Hostile and broken input for glTF import, manifests and confined paths:
 * no crash, no hang, bounded cost, one message per bad input
 * naming the file, the place and the reason.
 *
 * usage: test-hostile SOURCE_ROOT
 *
 * Every document is built here (the Kenney pieces shipped in
 * SOURCE_ROOT/tilesets/kenney-city stand in for real content), so nothing
 * outside the source tree is needed. Costs are bounded by counting
 * (resident memory in a child, against the importer's budget) or by a
 * generous CPU limit that only a quadratic or unbounded loop could reach;
 * never by the clock. */
#include "tileworld/tilesets.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "tilesets/confined-path.h"
#include "tests/base64.h"
#include "tests/check.h"
#include "tests/watchdog.h"
#include "tiles/tiles-internal.h"

#if defined(__SANITIZE_ADDRESS__)
#define UNDER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define UNDER_ASAN 1
#endif
#endif

static const char *source_root;
static char tmp[64];

/* ---- logs, text, files ------------------------------------------------------------ */

struct log_capture {
    char error[2048];
    char warning[2048];
    int errors, warnings;
    bool control;        /* a message held a control character */
};

static void capture(void *user, enum tw_log_level level, const char *msg)
{
    struct log_capture *c = user;
    for (const char *p = msg; *p; p++)
        c->control |= (unsigned char)*p < 0x20 || *p == 0x7f;
    if (level == TW_LOG_ERROR) {
        c->errors++;
        snprintf(c->error, sizeof(c->error), "%s", msg);
    } else if (level == TW_LOG_WARN) {
        c->warnings++;
        snprintf(c->warning, sizeof(c->warning), "%s", msg);
    }
}

static struct tw_log new_log(struct log_capture *c)
{
    memset(c, 0, sizeof(*c));
    const struct tw_log log = {capture, c};
    return log;
}

/* A malloc()ed printf. */
static char *format(const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 1, 2)))
#endif
    ;

static char *format(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    const int n = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    char *s = malloc((size_t)n + 1);
    if (!s)
        exit(3);
    va_start(ap, fmt);
    vsnprintf(s, (size_t)n + 1, fmt, ap);
    va_end(ap);
    return s;
}

static char *in_tmp(const char *name)
{
    return format("%s/%s", tmp, name);
}

static void write_file(const char *path, const void *data, size_t n)
{
    FILE *f = fopen(path, "wb");
    CHECK_MSG(f != NULL, "cannot write %s", path);
    if (f) {
        fwrite(data, 1, n, f);
        fclose(f);
    }
}

static void copy_kenney(const char *piece, const char *to)
{
    char *from = format("%s/tilesets/kenney-city/%s", source_root, piece);
    FILE *in = fopen(from, "rb");
    CHECK_MSG(in != NULL, "cannot read %s", from);
    if (in) {
        char buf[1 << 16];
        size_t n;
        FILE *out = fopen(to, "wb");
        while (out && (n = fread(buf, 1, sizeof(buf), in)) > 0)
            fwrite(buf, 1, n, out);
        if (out)
            fclose(out);
        fclose(in);
    }
    free(from);
}

static int import_text(const char *doc, const char *name, const char *dir,
                       struct log_capture *cap, struct tw_gltf_scene **s)
{
    const struct tw_log log = new_log(cap);
    *s = NULL;
    return tw_gltf_import_memory(doc, strlen(doc), name, dir, NULL, &log, s);
}

/* One triangle of float positions in a data: URI, 36 bytes. */
static char *triangle_uri(const float p[9])
{
    char b64[64];
    base64((const uint8_t *)p, 36, b64);
    return format("data:application/octet-stream;base64,%s", b64);
}

/* A document drawing one triangle (positions p) through nodes_json. */
static char *triangle_doc(const float p[9], const char *nodes_json, const char *extra)
{
    char *uri = triangle_uri(p);
    char *doc = format("{\"asset\":{\"version\":\"2.0\"},"
                       "\"buffers\":[{\"byteLength\":36,\"uri\":\"%s\"}],"
                       "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
                       "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                       "\"type\":\"VEC3\"}],"
                       "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                       "\"nodes\":%s%s%s}",
                       uri, nodes_json, extra ? "," : "", extra ? extra : "");
    free(uri);
    return doc;
}

static const float unit_triangle[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};

/* Expects doc to be refused with err and a message "name: want...". */
static void expect_refused(const char *what, const char *doc, int err_want, const char *want)
{
    struct log_capture cap;
    struct tw_gltf_scene *s = NULL;
    const int err = import_text(doc, "hostile.gltf", NULL, &cap, &s);
    char full[1024];
    snprintf(full, sizeof(full), "hostile.gltf: %s", want);
    CHECK_MSG(err == err_want && s == NULL && cap.errors == 1 && strncmp(cap.error, full,
                                                                          strlen(full)) == 0 &&
                  !cap.control,
              "%s: error %d, \"%s\"; expected %d, \"%s...\"", what, err, cap.error, err_want, full);
    tw_gltf_scene_destroy(s);
}

/* ---- class 1: huge but finite coordinates ------------------------------------------ */

static void test_coordinates(void)
{
    static const float far[9] = {0, 0, 0, 9e4f, 0, 0, 0, 1, 0};
    static const float huge[9] = {0, 0, 0, 3e38f, 0, 0, 0, 1, 0};
    static const struct {
        const char *what;
        const float *positions;
        const char *nodes, *want;
    } refused[] = {
        /* The audit's file: a translation near the float limit passed the
         * finiteness check and aborted in Embree's binning. */
        {"translation 3.4e38", unit_triangle,
         "[{\"children\":[1]},{\"children\":[3]},{},"
         "{\"mesh\":0,\"translation\":[3.4e38,0,0]}],"
         "\"scenes\":[{\"nodes\":[0,2]}]",
         "nodes[3].translation: 3.4e+38 is beyond +-1e+07"},
        {"matrix translation", unit_triangle,
         "[{\"mesh\":0,\"matrix\":[1,0,0,0,0,1,0,0,0,0,1,0,0,-2e30,0,1]}]",
         "nodes[0].matrix: -2e+30 is beyond"},
        /* Within a node's limit, but placed 200 km away. */
        {"composed translation", unit_triangle,
         "[{\"translation\":[1.5e5,0,0],\"children\":[1]},"
         "{\"mesh\":0,\"translation\":[5e4,0,0]}]",
         "nodes[1]: its transform, composed with its ancestors', has a translation of "
         "200000, beyond +-100000"},
        /* The mesh itself reaches beyond. */
        {"placed mesh", far, "[{\"mesh\":0,\"translation\":[5e4,0,0]}]",
         "nodes[0]: its mesh, placed by the node's transform composed with its "
         "ancestors', reaches x = 140000 m, beyond +-100000 m"},
        {"huge position", huge, "[{\"mesh\":0}]",
         "meshes[0].primitives[0].attributes.POSITION: accessors[0] element 1 has "
         "x = 3e+38, beyond +-1e+07"},
    };
    char *doc = NULL;
    for (size_t k = 0; k < sizeof(refused) / sizeof(refused[0]); k++) {
        doc = triangle_doc(refused[k].positions, refused[k].nodes, NULL);
        expect_refused(refused[k].what, doc, TW_ERR_LIMIT, refused[k].want);
        free(doc);
    }
    /* Millimetres placed by a 0.001 scale: fine. */
    const float mm[9] = {0, 0, 0, 5e6f, 0, 0, 0, 5e6f, 0};
    doc = triangle_doc(mm, "[{\"mesh\":0,\"scale\":[0.001,0.001,0.001]}]", NULL);
    struct log_capture cap;
    struct tw_gltf_scene *s = NULL;
    CHECK_MSG(import_text(doc, "mm.gltf", NULL, &cap, &s) == 0 && fabsf(s->bounds.max[0] - 5000) < 1,
              "millimetres: %s", cap.error);
    tw_gltf_scene_destroy(s);
    free(doc);
}

/* ---- class 6: import cost bounded by the file ---------------------------------------- */

/* The peak resident memory of this process in bytes (Linux's VmHWM, which
 * writing 5 to /proc/self/clear_refs resets to the current size; else
 * getrusage()'s, which only grows). */
static long long peak_rss(bool reset)
{
    if (reset) {
        FILE *f = fopen("/proc/self/clear_refs", "w");
        if (f) {
            fputs("5", f);
            fclose(f);
        }
    }
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    long long kb = -1;
    while (f && fgets(line, sizeof(line), f))
        if (sscanf(line, "VmHWM: %lld kB", &kb) == 1)
            break;
    if (f)
        fclose(f);
    if (kb < 0) {
        struct rusage ru;
        getrusage(RUSAGE_SELF, &ru);
        kb = ru.ru_maxrss;
    }
    return kb * 1024;
}

/* Runs fn in a child under a CPU limit of cpu_seconds and returns the growth
 * of its peak resident memory in bytes (-1 if the child did not exit 0). */
static long long in_child(void (*fn)(void *), void *arg, int cpu_seconds, const char *what)
{
    fflush(NULL);
    const pid_t pid = fork();
    if (pid == 0) {
        const struct rlimit cpu = {(rlim_t)cpu_seconds, (rlim_t)cpu_seconds};
        setrlimit(RLIMIT_CPU, &cpu);
        const long long before = peak_rss(true);
        fn(arg);
        const long long grown = peak_rss(false) - before;
        printf("  %s: peak memory grew %lld MiB\n", what, grown >> 20);
        fflush(stdout);
        /* Through the exit status, in MiB. */
        _exit(failures ? 255 : (int)(grown >> 20 > 254 ? 254 : grown >> 20));
    }
    int status = 0;
    CHECK_MSG(pid > 0 && waitpid(pid, &status, 0) == pid, "fork");
    CHECK_MSG(WIFEXITED(status) && WEXITSTATUS(status) != 255,
              "%s: the child %s %d%s", what, WIFEXITED(status) ? "exited with" : "died of signal",
              WIFEXITED(status) ? WEXITSTATUS(status) : WTERMSIG(status),
              WIFSIGNALED(status) && WTERMSIG(status) == SIGXCPU ? " (SIGXCPU: over the CPU limit)"
                                                                 : "");
    if (!WIFEXITED(status) || WEXITSTATUS(status) == 255)
        return -1;
    return (long long)WEXITSTATUS(status) << 20;
}

struct big_doc {
    char *text;
    size_t size;
    int want_err;
    const char *want;
};

static void import_big(void *arg)
{
    const struct big_doc *b = arg;
    struct log_capture cap;
    const struct tw_log log = new_log(&cap);
    struct tw_gltf_scene *s = NULL;
    const struct tw_gltf_settings limits = {64u << 20, 0};
    const int err = tw_gltf_import_memory(b->text, b->size, "big.gltf", NULL, &limits, &log, &s);
    CHECK_MSG(err == b->want_err && (!b->want || strstr(cap.error, b->want)),
              "big document: error %d, \"%s\"; expected %d, \"%s\"", err, cap.error, b->want_err,
              b->want ? b->want : "");
    printf("  %zu bytes: %s\n", b->size, err ? cap.error : "imported");
    tw_gltf_scene_destroy(s);
}

/* "{...prefix,"nodes":[node x count],"scenes":[{"nodes":[0..roots-1,dup]}]}" */
static struct big_doc nodes_doc(const char *node, uint32_t count, uint32_t roots, bool dup)
{
    char *uri = triangle_uri(unit_triangle);
    char *head = format("{\"asset\":{\"version\":\"2.0\"},"
                        "\"buffers\":[{\"byteLength\":36,\"uri\":\"%s\"}],"
                        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
                        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                        "\"type\":\"VEC3\"}],"
                        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                        "\"nodes\":[",
                        uri);
    free(uri);
    const size_t nl = strlen(node), hl = strlen(head);
    const size_t cap = hl + (nl + 1) * count + 12 * (size_t)roots + 64;
    char *t = malloc(cap);
    if (!t)
        exit(3);
    size_t n = 0;
    memcpy(t, head, hl);
    n += hl;
    free(head);
    for (uint32_t k = 0; k < count; k++) {
        if (k)
            t[n++] = ',';
        memcpy(t + n, node, nl);
        n += nl;
    }
    n += (size_t)snprintf(t + n, cap - n, "],\"scenes\":[{\"nodes\":[");
    for (uint32_t k = 0; k < roots; k++)
        n += (size_t)snprintf(t + n, cap - n, "%s%u", k ? "," : "", k);
    if (dup)
        n += (size_t)snprintf(t + n, cap - n, ",0");
    n += (size_t)snprintf(t + n, cap - n, "]}],\"scene\":0}");
    struct big_doc b = {t, n, 0, NULL};
    return b;
}

static void test_import_cost(void)
{
    /* The audit's first file: 10^6 root nodes in 10 MB. The duplicate check
     * was quadratic (minutes); now the document is refused before
     * tinygltf sees it, its memory estimate being over the budget. A CPU
     * limit of 60 s (seconds are needed) catches a quadratic step. */
    struct big_doc b = nodes_doc("{}", 1000000, 1000000, false);
    b.want_err = TW_ERR_LIMIT;
    b.want = "would take about";
    long long grown = in_child(import_big, &b, 60, "10^6 root nodes");
    free(b.text);
#ifndef UNDER_ASAN
    CHECK_MSG(grown >= 0 && grown <= (64ll << 20), "10^6 roots: peak memory grew %lld MiB",
              grown >> 20);
#endif

    /* The second: 8 MB of empty nodes peaked at 1.7 GB. */
    b = nodes_doc("{}", 2796000, 0, false);
    b.want_err = TW_ERR_LIMIT;
    b.want = "JSON: importing its";
    grown = in_child(import_big, &b, 60, "8 MB of empty nodes");
#ifndef UNDER_ASAN
    CHECK_MSG(grown >= 0 && grown <= (64ll << 20), "empty nodes: peak memory grew %lld MiB",
              grown >> 20);
#endif
    free(b.text);

    /* A real scene of 100000 placed instances imports within its budget
     * (64 MiB + 32 bytes per byte of JSON), and a root listed twice at the
     * end of 100000 is found (by a linear check). */
    b = nodes_doc("{\"mesh\":0,\"translation\":[1.25,0,-2.5]}", 100000, 100000, false);
    const long long budget = (64ll << 20) + 32ll * (long long)b.size;
    grown = in_child(import_big, &b, 60, "100000 instances");
#ifndef UNDER_ASAN
    CHECK_MSG(grown >= 0 && grown <= budget, "100000 instances: peak memory grew %lld MiB, budget %lld",
              grown >> 20, budget >> 20);
#endif
    printf("  100000 instances: peak memory grew %lld MiB (budget %lld MiB)\n", grown >> 20,
           budget >> 20);
    free(b.text);
    b = nodes_doc("{\"mesh\":0,\"translation\":[1.25,0,-2.5]}", 100000, 100000, true);
    b.want_err = TW_ERR_FORMAT;
    b.want = "scenes[0].nodes[100000]: nodes[0] is listed twice";
    in_child(import_big, &b, 60, "a root listed twice");
    free(b.text);
}

/* ---- class 7: valid files ----------------------------------------------------------- */

/* A 2 x 1 PNG: red, then blue. */
static const char two_pixels[] =
    "iVBORw0KGgoAAAANSUhEUgAAAAIAAAABCAIAAAB7QOjdAAAADUlEQVR4nGP4zwAE/wEHAAH/4iOeWQAAAABJRU5Er"
    "kJggg==";

static void test_quantized(void)
{
    /* What gltfpack writes: SHORT positions (dequantised by the node's
     * scale), normalized BYTE normals, unnormalized UNSIGNED_SHORT texture
     * coordinates (dequantised by KHR_texture_transform), each attribute
     * padded to 4-byte strides. */
    uint8_t bytes[48];
    memset(bytes, 0, sizeof(bytes));
    const int16_t pos[3][4] = {{0, 0, 0, 0}, {1000, 0, 0, 0}, {0, 1000, 0, 0}};
    memcpy(bytes, pos, 24);
    for (int v = 0; v < 3; v++) {
        bytes[24 + 4 * v + 2] = 127;   /* normal (0, 0, 1) */
        const uint16_t uv[2] = {(uint16_t)(v == 1), (uint16_t)(v == 2)};
        memcpy(bytes + 36 + 4 * v, uv, 4);
    }
    char b64[128];
    base64(bytes, sizeof(bytes), b64);
    const char *transform[2] = {"", ",\"extensions\":{\"KHR_texture_transform\":{\"scale\":[2,1]}}"};
    for (int t = 0; t < 2; t++) {
        char *doc = format(
            "{\"asset\":{\"version\":\"2.0\"},"
            "\"extensionsUsed\":[\"KHR_mesh_quantization\",\"KHR_texture_transform\"],"
            "\"extensionsRequired\":[\"KHR_mesh_quantization\"],"
            "\"buffers\":[{\"byteLength\":48,\"uri\":\"data:application/octet-stream;base64,%s\"}],"
            "\"bufferViews\":[{\"buffer\":0,\"byteLength\":24,\"byteStride\":8},"
            "{\"buffer\":0,\"byteOffset\":24,\"byteLength\":12,\"byteStride\":4},"
            "{\"buffer\":0,\"byteOffset\":36,\"byteLength\":12,\"byteStride\":4}],"
            "\"accessors\":[{\"bufferView\":0,\"componentType\":5122,\"count\":3,\"type\":\"VEC3\"},"
            "{\"bufferView\":1,\"componentType\":5120,\"normalized\":true,\"count\":3,"
            "\"type\":\"VEC3\"},"
            "{\"bufferView\":2,\"componentType\":5123,\"count\":3,\"type\":\"VEC2\"}],"
            "\"images\":[{\"uri\":\"data:image/png;base64,%s\"}],\"textures\":[{\"source\":0}],"
            "\"materials\":[{\"pbrMetallicRoughness\":{\"baseColorTexture\":{\"index\":0%s}}}],"
            "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0,\"NORMAL\":1,"
            "\"TEXCOORD_0\":2},\"material\":0}]}],"
            "\"nodes\":[{\"mesh\":0,\"scale\":[0.001,0.001,0.001]}],\"scenes\":[{\"nodes\":[0]}]}",
            b64, two_pixels, transform[t]);
        struct log_capture cap;
        struct tw_gltf_scene *s = NULL;
        const int err = import_text(doc, "quantized.gltf", NULL, &cap, &s);
        CHECK_MSG(err == 0, "quantized: %s", cap.error);
        if (!err) {
            const struct tw_gltf_primitive *p = &s->primitives[0];
            CHECK_MSG(p->positions[3] == 1000.0f && p->positions[7] == 1000.0f,
                      "positions read as integers: %g %g", p->positions[3], p->positions[7]);
            CHECK_MSG(fabsf(s->bounds.max[0] - 1.0f) < 1e-5f && fabsf(s->bounds.max[1] - 1.0f) < 1e-5f,
                      "dequantised by the node: bounds to %g, %g", s->bounds.max[0], s->bounds.max[1]);
            CHECK_MSG(p->normals && fabsf(p->normals[2] - 1.0f) < 1e-6f && p->normals[0] == 0.0f,
                      "normals dequantised");
            /* The centroid's u is 1/3: red without the transform, 2/3 (blue)
             * with it. */
            const float *c = s->materials[p->material].base_color;
            if (t == 0)
                CHECK_MSG(c[0] > 0.9f && c[2] < 0.1f, "untransformed: %g %g %g", c[0], c[1], c[2]);
            else
                CHECK_MSG(c[2] > 0.9f && c[0] < 0.1f, "KHR_texture_transform: %g %g %g", c[0], c[1],
                          c[2]);
        }
        tw_gltf_scene_destroy(s);
        free(doc);
    }
    /* Positions of UNSIGNED_INT are in no specification. */
    char *doc = format("{\"asset\":{\"version\":\"2.0\"},"
                       "\"buffers\":[{\"byteLength\":48,\"uri\":\"data:application/octet-stream;"
                       "base64,%s\"}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
                       "\"accessors\":[{\"bufferView\":0,\"componentType\":5125,\"count\":3,"
                       "\"type\":\"VEC3\"}],"
                       "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                       "\"nodes\":[{\"mesh\":0}]}",
                       b64);
    expect_refused("UNSIGNED_INT positions", doc, TW_ERR_FORMAT,
                   "meshes[0].primitives[0].attributes.POSITION: accessors[0] is VEC3 of "
                   "UNSIGNED_INT; positions must be VEC3 of FLOAT, or of BYTE");
    free(doc);
}

static void test_valid_files(void)
{
    /* A LINES primitive beside triangles: skipped with one warning, the
     * file imports. */
    char *uri = triangle_uri(unit_triangle);
    char *doc = format("{\"asset\":{\"version\":\"2.0\"},"
                       "\"buffers\":[{\"byteLength\":36,\"uri\":\"%s\"}],"
                       "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
                       "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                       "\"type\":\"VEC3\"}],"
                       "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"mode\":1},"
                       "{\"attributes\":{\"POSITION\":0}},"
                       "{\"attributes\":{\"POSITION\":0},\"mode\":0}]}],"
                       "\"nodes\":[{\"mesh\":0}]}",
                       uri);
    struct log_capture cap;
    struct tw_gltf_scene *s = NULL;
    int err = import_text(doc, "lines.gltf", NULL, &cap, &s);
    CHECK_MSG(err == 0 && s->primitive_count == 1 && s->triangle_count == 1, "lines: %s", cap.error);
    CHECK_MSG(cap.warnings == 1 &&
                  strcmp(cap.warning, "lines.gltf: meshes[0].primitives[0].mode: 1 (LINES) and 1 "
                                      "more point or line primitives are not drawn: only "
                                      "triangles, triangle strips and triangle fans are") == 0,
              "lines: %d warnings, last \"%s\"", cap.warnings, cap.warning);
    tw_gltf_scene_destroy(s);
    free(doc);

    /* A Draco file: its primitives' accessors have no buffer view, which
     * tinygltf reported first as "invalid bufferView". */
    doc = format("{\"asset\":{\"version\":\"2.0\"},"
                 "\"extensionsUsed\":[\"KHR_draco_mesh_compression\"],"
                 "\"extensionsRequired\":[\"KHR_draco_mesh_compression\"],"
                 "\"buffers\":[{\"byteLength\":36,\"uri\":\"%s\"}],"
                 "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
                 "\"accessors\":[{\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"},"
                 "{\"componentType\":5123,\"count\":3,\"type\":\"SCALAR\"}],"
                 "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,"
                 "\"extensions\":{\"KHR_draco_mesh_compression\":{\"bufferView\":0,"
                 "\"attributes\":{\"POSITION\":0}}}}]}],"
                 "\"nodes\":[{\"mesh\":0}]}",
                 uri);
    expect_refused("Draco", doc, TW_ERR_FORMAT,
                   "extensionsRequired[0]: \"KHR_draco_mesh_compression\" is not supported "
                   "(Draco-compressed geometry");
    free(doc);
    free(uri);

    /* '+' in a buffer's file name is a plus sign (tinygltf's decoder read it
     * as a space: "lod 1.bin does not exist"); %20 is a space. */
    char *folder = in_tmp("uris");
    mkdir(folder, 0755);
    const char *names[][2] = {{"lod+1.bin", "lod+1.bin"},
                              {"lod%2B2.bin", "lod+2.bin"},
                              {"with%20space.bin", "with space.bin"},
                              {"sub/a+b%2Bc.bin", "sub/a+b+c.bin"}};
    char *sub = in_tmp("uris/sub");
    mkdir(sub, 0755);
    free(sub);
    for (size_t k = 0; k < sizeof(names) / sizeof(names[0]); k++) {
        char *bin = format("%s/%s", folder, names[k][1]);
        write_file(bin, unit_triangle, sizeof(unit_triangle));
        free(bin);
        char *text = format("{\"asset\":{\"version\":\"2.0\"},"
                            "\"buffers\":[{\"byteLength\":36,\"uri\":\"%s\"}],"
                            "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
                            "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                            "\"type\":\"VEC3\"}],"
                            "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                            "\"nodes\":[{\"mesh\":0}]}",
                            names[k][0]);
        char *gltf = format("%s/doc%zu.gltf", folder, k);
        write_file(gltf, text, strlen(text));
        const struct tw_log log = new_log(&cap);
        err = tw_gltf_import(gltf, NULL, &log, &s);
        CHECK_MSG(err == 0 && s->triangle_count == 1, "buffer uri %s: %s", names[k][0], cap.error);
        tw_gltf_scene_destroy(s);
        free(gltf);
        free(text);
    }
    /* Two buffers whose URIs tinygltf decodes alike: each reads its own. */
    {
        char *bin = format("%s/a b.bin", folder);
        const float other[9] = {0, 0, 0, 4, 0, 0, 0, 4, 0};
        write_file(bin, other, sizeof(other));
        free(bin);
        char *text = format("{\"asset\":{\"version\":\"2.0\"},"
                            "\"buffers\":[{\"byteLength\":36,\"uri\":\"a%%20b.bin\"},"
                            "{\"byteLength\":36,\"uri\":\"a+b.bin\"}],"
                            "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36},"
                            "{\"buffer\":1,\"byteLength\":36}],"
                            "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                            "\"type\":\"VEC3\"},{\"bufferView\":1,\"componentType\":5126,"
                            "\"count\":3,\"type\":\"VEC3\"}],"
                            "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":1}}]}],"
                            "\"nodes\":[{\"mesh\":0}]}");
        bin = format("%s/a+b.bin", folder);
        write_file(bin, unit_triangle, sizeof(unit_triangle));
        free(bin);
        char *gltf = format("%s/two.gltf", folder);
        write_file(gltf, text, strlen(text));
        const struct tw_log log = new_log(&cap);
        err = tw_gltf_import(gltf, NULL, &log, &s);
        CHECK_MSG(err == 0 && fabsf(s->bounds.max[0] - 1.0f) < 1e-6f,
                  "a+b.bin and a%%20b.bin: %s, bounds %g", cap.error, s ? s->bounds.max[0] : -1.0);
        tw_gltf_scene_destroy(s);
        free(gltf);
        free(text);
    }
    free(folder);
}

/* ---- class 5: control characters ------------------------------------------------------- */

static void test_escapes(void)
{
    char *doc = triangle_doc(unit_triangle, "[{\"mesh\":0}]",
                             "\"extensionsRequired\":[\"\\u001b[2J\\nforged: ok\"]");
    expect_refused("escape in an extension name", doc, TW_ERR_FORMAT,
                   "extensionsRequired[0]: \"\\x1b[2J\\nforged: ok\" is not supported");
    free(doc);
    struct log_capture cap;
    struct tw_gltf_scene *s = NULL;
    doc = triangle_doc(unit_triangle, "[{\"mesh\":0}]", NULL);
    int err = import_text(doc, "evil\x1b]0;title\a.gltf", NULL, &cap, &s);
    CHECK_MSG(err == 0, "escape in a file name: %s", cap.error);
    tw_gltf_scene_destroy(s);
    free(doc);
    doc = format("{\"asset\":{\"version\":\"2.0\"},\"meshes\":[{\"primitives\":[{\"attributes\":"
                 "{\"\\u009b31m\":7}}]}],\"nodes\":[{\"mesh\":0}]}");
    err = import_text(doc, "evil\x1b[2J.gltf", NULL, &cap, &s);
    CHECK_MSG(err == TW_ERR_FORMAT && !cap.control &&
                  strstr(cap.error, "evil\\x1b[2J.gltf: meshes[0].primitives[0].attributes."
                                    "\\u009b31m: 7 is not an accessor"),
              "escaped attribute: \"%s\"", cap.error);
    free(doc);
}

/* ---- manifests: classes 2, 4, 5, 9 ------------------------------------------------------- */

static int load_manifest(const char *text, struct log_capture *cap, struct tw_tileset **ts)
{
    char *path = in_tmp("m/test.json");
    write_file(path, text, strlen(text));
    const struct tw_log log = new_log(cap);
    *ts = NULL;
    const int err = tw_tilesets_load_manifest(path, NULL, &log, ts);
    free(path);
    return err;
}

static void expect_manifest(const char *what, const char *text, int err_want, const char *want)
{
    struct log_capture cap;
    struct tw_tileset *ts = NULL;
    const int err = load_manifest(text, &cap, &ts);
    char *path = in_tmp("m/test.json");
    char *full = format("%s: %s", path, want);
    CHECK_MSG(err == err_want && ts == NULL && cap.errors == 1 &&
                  strncmp(cap.error, full, strlen(full)) == 0 && !cap.control,
              "%s: error %d, \"%s\"; expected %d, \"%s...\"", what, err, cap.error, err_want, full);
    free(full);
    free(path);
    tw_tileset_destroy(ts);
}

static void test_manifests(void)
{
    char *m = in_tmp("m");
    mkdir(m, 0755);
    char *road = in_tmp("m/road.glb");
    char *house = in_tmp("m/house.glb");
    copy_kenney("road-straight.glb", road);
    copy_kenney("building-small-a.glb", house);

    /* Class 2: a 1 cm footprint asks 10^10 cells of every frame. */
    expect_manifest("1 cm tiles",
                    "{\"footprint\": [0.01, 0.01], \"prototypes\": [{\"name\": \"a\", "
                    "\"gltf\": \"road.glb\"}]}",
                    TW_ERR_LIMIT,
                    "footprint: tiles on 0.01 x 0.01 m tiles: a frame at the default view "
                    "distance of 600 m would consider about 1.44e+10 cells, more than the "
                    "limit of 65536 (tiles of 4.72 m or more");
    expect_manifest("1e-30 tiles",
                    "{\"footprint\": [1e-30, 10], \"prototypes\": [{\"name\": \"a\", "
                    "\"gltf\": \"road.glb\"}]}",
                    TW_ERR_LIMIT, "footprint: tiles on 1e-30 x 10 m tiles");
    /* ... and a scale of 10^6 makes a prototype 1000 km wide. */
    expect_manifest("scale 1e6",
                    "{\"footprint\": [10, 10], \"prototypes\": [{\"name\": \"a\", "
                    "\"gltf\": \"road.glb\", \"scale\": 1e6}]}",
                    TW_ERR_LIMIT, "prototypes[0]: the placed scene reaches x = -500000 m, beyond "
                                  "+-100000 m of the tile (scale 1e+06");
    expect_manifest("scale 100",
                    "{\"footprint\": [10, 10], \"prototypes\": [{\"name\": \"a\", "
                    "\"objects\": [{\"gltf\": \"road.glb\", \"scale\": 100}]}]}",
                    TW_ERR_LIMIT,
                    "prototypes[0].objects[0]: the placed scene spans 100 m along x, more than 8 "
                    "footprints (80 m)");
    /* Class 9: a weight of 1e-300 is 0 as a float. */
    expect_manifest("weight 1e-300",
                    "{\"footprint\": [10, 10], \"prototypes\": [{\"name\": \"a\", "
                    "\"gltf\": \"road.glb\", \"weight\": 1e-300}]}",
                    TW_ERR_FORMAT, "prototypes[0].weight: 1e-300 is not in [1e-06, 1e+06]");
    expect_manifest("scale 1e-300",
                    "{\"footprint\": [10, 10], \"prototypes\": [{\"name\": \"a\", "
                    "\"gltf\": \"road.glb\", \"scale\": 1e-300}]}",
                    TW_ERR_FORMAT, "prototypes[0].scale: 1e-300 is not in [1e-06, 1e+06]");
    /* Class 5: keys, names and paths reach the message escaped; names that
     * are printed later may hold no control character at all. */
    expect_manifest("escape in a key",
                    "{\"footprint\": [10, 10], \"\\u001b[2J\\u001b[H\\nok\": 1, \"prototypes\": []}",
                    TW_ERR_FORMAT, "(top level): unknown key \"\\x1b[2J\\x1b[H\\nok\"");
    expect_manifest("escape in a name",
                    "{\"footprint\": [10, 10], \"prototypes\": [{\"name\": \"a\\u001b[31m\", "
                    "\"gltf\": \"road.glb\"}]}",
                    TW_ERR_FORMAT,
                    "prototypes[0].name: \"a\\x1b[31m\" contains a control character at byte 1");
    expect_manifest("C1 in a tileset name",
                    "{\"name\": \"x\\u009by\", \"footprint\": [10, 10], \"prototypes\": "
                    "[{\"name\": \"a\", \"gltf\": \"road.glb\"}]}",
                    TW_ERR_FORMAT, "name: \"x\\u009by\" contains a control character at byte 1");
    expect_manifest("escape in a path",
                    "{\"footprint\": [10, 10], \"prototypes\": [{\"name\": \"a\", "
                    "\"gltf\": \"\\u001b[2J.glb\"}]}",
                    TW_ERR_IO, "prototypes[0].gltf: \"\\x1b[2J.glb\" does not exist");
    /* Many objects naming one file a few ways: one import, shared. */
    {
        char *text = malloc(4 << 20);
        size_t n = (size_t)snprintf(text, 4 << 20, "{\"footprint\": [60, 60], \"prototypes\": "
                                                   "[{\"name\": \"a\", \"objects\": [");
        for (int k = 0; k < 20000; k++)
            n += (size_t)snprintf(text + n, (4 << 20) - n,
                                  "%s{\"gltf\": \"%sroad.glb\", \"position\": [%d, 0, %d]}",
                                  k ? "," : "", k % 3 == 0 ? "" : k % 3 == 1 ? "./" : "x/../",
                                  k % 50, k / 400);
        snprintf(text + n, (4 << 20) - n, "]}]}");
        char *x = in_tmp("m/x");
        mkdir(x, 0755);
        free(x);
        struct log_capture cap;
        struct tw_tileset *ts = NULL;
        const int err = load_manifest(text, &cap, &ts);
        /* Instances that tw_tileset_finish() made by merging small ones
         * (and their meshes) are not the manifest's. */
        uint32_t placed = 0, merged_meshes = 0;
        for (uint32_t k = 0; ts && k < ts->prototypes[0].instance_count; k++) {
            placed += !ts->prototypes[0].instances[k].merged;
            merged_meshes += ts->prototypes[0].instances[k].merged;
        }
        CHECK_MSG(err == 0 && ts && placed == 20000 * (ts->mesh_count - merged_meshes),
                  "20000 objects: %s", cap.error);
        tw_tileset_destroy(ts);
        free(text);
    }

    /* Class 4: a FIFO as the manifest is refused, not waited on. */
    char *fifo = in_tmp("m/fifo.json");
    CHECK_MSG(mkfifo(fifo, 0600) == 0, "mkfifo");
    watchdog_arm(20, "test-hostile: blocked on a FIFO\n");
    struct log_capture cap;
    const struct tw_log log = new_log(&cap);
    struct tw_tileset *ts = NULL;
    int err = tw_tilesets_load_manifest(fifo, NULL, &log, &ts);
    watchdog_disarm();
    char *want = format("%s: is not a regular file (a FIFO)", fifo);
    CHECK_MSG(err == TW_ERR_IO && ts == NULL && strcmp(cap.error, want) == 0, "FIFO manifest: %s",
              cap.error);
    free(want);
    unlink(fifo);
    free(fifo);
    /* ... and so is /dev/zero. */
    err = tw_tilesets_load_manifest("/dev/zero", NULL, &log, &ts);
    CHECK_MSG(err == TW_ERR_IO && strstr(cap.error, "/dev/zero: is not a regular file (a device)"),
              "/dev/zero: %s", cap.error);
    free(road);
    free(house);
    free(m);
}

/* ---- class 11: opening beneath a folder ------------------------------------------------- */

static void test_confined(void)
{
    char *root = in_tmp("c");
    char *dir = in_tmp("c/in");
    mkdir(root, 0755);
    mkdir(dir, 0755);
    char *sub = in_tmp("c/in/sub");
    mkdir(sub, 0755);
    char *file = in_tmp("c/in/sub/f.bin");
    write_file(file, "data", 4);
    char *secret = in_tmp("c/secret.bin");
    write_file(secret, "secret", 6);
    const struct {
        const char *name, *target;
    } links[] = {
        {"c/in/inside", "sub/f.bin"},            /* stays inside: followed */
        {"c/in/subdir", "sub"},
        {"c/in/up", "../secret.bin"},            /* leaves: refused */
        {"c/in/sub/upup", "../../secret.bin"},
        {"c/in/abs", NULL},                      /* absolute: refused */
        {"c/in/proc", "/proc/self/fd/0"},        /* a magic link */
        {"c/in/loop", "loop"},
        {"c/in/uplink", ".."},
    };
    for (size_t k = 0; k < sizeof(links) / sizeof(links[0]); k++) {
        char *at = in_tmp(links[k].name);
        CHECK_MSG(symlink(links[k].target ? links[k].target : secret, at) == 0, "symlink %s",
                  links[k].name);
        free(at);
    }
    char *hard = in_tmp("c/in/hard.bin");
    CHECK_MSG(link(secret, hard) == 0, "link");
    char *fifo = in_tmp("c/in/fifo");
    CHECK_MSG(mkfifo(fifo, 0600) == 0, "mkfifo");
    const int dir_fd = tw_confined_open_folder(dir);
    CHECK_MSG(dir_fd >= 0, "open the folder");
    const struct {
        const char *rel;
        int err;
        const char *reason;     /* NULL: opens; then the first 4 bytes read */
        const char *bytes;
    } cases[] = {
        {"sub/f.bin", 0, NULL, "data"},
        {"./sub//f.bin", 0, NULL, "data"},
        {"sub/../sub/f.bin", 0, NULL, "data"},
        {"inside", 0, NULL, "data"},
        {"subdir/f.bin", 0, NULL, "data"},
        {"hard.bin", 0, NULL, "secr"},   /* a hard link is the folder owner's own */
        {"up", TW_ERR_FORMAT, "resolves outside the document's folder", NULL},
        {"sub/upup", TW_ERR_FORMAT, "resolves outside the document's folder", NULL},
        {"abs", TW_ERR_FORMAT, "resolves outside the document's folder", NULL},
        {"uplink/secret.bin", TW_ERR_FORMAT, "resolves outside the document's folder", NULL},
        {"proc", TW_ERR_FORMAT, NULL, NULL},
        {"loop", TW_ERR_FORMAT, "goes through too many symbolic links", NULL},
        {"../secret.bin", TW_ERR_FORMAT, "climbs out of the document's folder", NULL},
        {"/etc/hostname", TW_ERR_FORMAT, "is an absolute path", NULL},
        {"file:f.bin", TW_ERR_FORMAT, "is a URI", NULL},
        {"missing", TW_ERR_IO, "does not exist", NULL},
        {"sub", TW_ERR_FORMAT, "is a folder, not a file", NULL},
        {".", TW_ERR_FORMAT, "is the document's folder, not a file", NULL},
        {"sub/f.bin/x", TW_ERR_IO, "has a component that is not a folder", NULL},
        {"fifo", TW_ERR_IO, "is not a regular file", NULL},
    };
    for (int mode = 0; mode < 2; mode++) {
        for (size_t k = 0; k < sizeof(cases) / sizeof(cases[0]); k++) {
            int fd = -1;
            const char *reason = NULL;
            const int err = tw_confined_open(dir_fd, cases[k].rel, (enum tw_confined_mode)mode,
                                             &fd, &reason);
            char got[8] = "";
            if (fd >= 0) {
                const ssize_t n = read(fd, got, 4);
                got[n > 0 ? n : 0] = '\0';
                close(fd);
            }
            CHECK_MSG(err == cases[k].err && (err ? fd < 0 : fd >= 0) &&
                          (!cases[k].reason || (reason && strstr(reason, cases[k].reason))) &&
                          (!cases[k].bytes || strcmp(got, cases[k].bytes) == 0),
                      "%s (%s): error %d, \"%s\", read \"%s\"", cases[k].rel,
                      mode ? "walk" : "openat2", err, reason ? reason : "", got);
        }
        /* The folder of a file beneath. */
        int fd = -1;
        const char *reason = NULL;
        CHECK_MSG(tw_confined_open_parent(dir_fd, "subdir/f.bin", (enum tw_confined_mode)mode, &fd,
                                          &reason) == 0 && fd >= 0,
                  "parent: %s", reason ? reason : "");
        if (fd >= 0) {
            int f2 = -1;
            CHECK_MSG(tw_confined_open(fd, "f.bin", (enum tw_confined_mode)mode, &f2, &reason) == 0,
                      "beneath the parent");
            if (f2 >= 0)
                close(f2);
            close(fd);
        }
        CHECK_MSG(tw_confined_open_parent(dir_fd, "up/x", (enum tw_confined_mode)mode, &fd,
                                          &reason) != 0 && fd < 0,
                  "parent through an escaping link");
    }
    close(dir_fd);
    free(root);
    free(dir);
    free(sub);
    free(file);
    free(secret);
    free(hard);
    free(fifo);
}

/* ---- the glTF specification's refusals ----------------------------------------------- */

/* A document drawing one triangle, with the given "asset" and extra members. */
static char *asset_doc(const char *asset, const char *extra)
{
    char *uri = triangle_uri(unit_triangle);
    char *doc = format("{\"asset\":%s,"
                       "\"buffers\":[{\"byteLength\":36,\"uri\":\"%s\"}],"
                       "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
                       "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                       "\"type\":\"VEC3\"}],"
                       "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                       "\"nodes\":[{\"mesh\":0}]%s%s}",
                       asset, uri, extra ? "," : "", extra ? extra : "");
    free(uri);
    return doc;
}

static void expect_imports(const char *what, const char *doc)
{
    struct log_capture cap;
    struct tw_gltf_scene *s = NULL;
    const int err = import_text(doc, "fine.gltf", NULL, &cap, &s);
    CHECK_MSG(err == 0 && s && cap.errors == 0, "%s: %s", what, cap.error);
    tw_gltf_scene_destroy(s);
}

/* A document of the given buffer bytes (base64 in a data: URI) and JSON
 * members. */
static char *buffer_doc(const void *bytes, size_t n, const char *members)
{
    char *b64 = malloc(4 * (n / 3 + 1) + 1);
    if (!b64)
        exit(3);
    base64(bytes, n, b64);
    char *doc = format("{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":%zu,"
                       "\"uri\":\"data:application/octet-stream;base64,%s\"}],%s}",
                       n, b64, members);
    free(b64);
    return doc;
}

static void test_spec(void)
{
    static const struct {
        const char *what, *asset, *extra, *want;
    } refused[] = {
        {"glTF 3", "{\"version\":\"3.0\"}", NULL,
         "asset.version: \"3.0\" is glTF 3; this importer reads glTF 2.x"},
        {"version 2", "{\"version\":\"2\"}", NULL, "asset.version: \"2\" is not <major>.<minor>"},
        {"version 2.x", "{\"version\":\"2.x\"}", NULL,
         "asset.version: \"2.x\" is not <major>.<minor>"},
        {"version a number", "{\"version\":2.0}", NULL,
         "asset.version: must be a string such as \"2.0\""},
        {"no version", "{\"generator\":\"x\"}", NULL, "asset.version: is missing"},
        {"minVersion above version", "{\"version\":\"2.0\",\"minVersion\":\"2.1\"}", NULL,
         "asset.minVersion: \"2.1\" is greater than asset.version \"2.0\""},
        {"minVersion 2.1", "{\"version\":\"2.1\",\"minVersion\":\"2.1\"}", NULL,
         "asset.minVersion: \"2.1\": the document needs a glTF 2.1 reader; this importer "
         "reads glTF 2.0"},
        {"minVersion 3.0", "{\"version\":\"3.1\",\"minVersion\":\"3.0\"}", NULL,
         "asset.version: \"3.1\" is glTF 3"},
        {"GPU instancing required", "{\"version\":\"2.0\"}",
         "\"extensionsRequired\":[\"EXT_mesh_gpu_instancing\"]",
         "extensionsRequired[0]: \"EXT_mesh_gpu_instancing\" is not supported (GPU instancing"},
        {"unknown material extension required", "{\"version\":\"2.0\"}",
         "\"extensionsRequired\":[\"KHR_materials_unlit\",\"KHR_materials_bogus\"]",
         "extensionsRequired[1]: \"KHR_materials_bogus\" is not supported"},
        {"no buffer uri", "{\"version\":\"2.0\"}",
         "\"scenes\":[{\"nodes\":[0]}],\"animations\":[],\"buffers\":[{\"byteLength\":4}]",
         "buffers[0]: has no uri (only a .glb's first buffer may omit it)"},
    };
    for (size_t k = 0; k < sizeof(refused) / sizeof(refused[0]); k++) {
        char *doc = asset_doc(refused[k].asset, refused[k].extra);
        expect_refused(refused[k].what, doc, TW_ERR_FORMAT, refused[k].want);
        free(doc);
    }
    static const struct {
        const char *what, *asset, *extra;
    } accepted[] = {
        {"minVersion 2.0", "{\"version\":\"2.0\",\"minVersion\":\"2.0\"}", NULL},
        {"version 2.5", "{\"version\":\"2.5\"}", NULL},
        {"material extensions required", "{\"version\":\"2.0\"}",
         "\"extensionsRequired\":[\"KHR_materials_unlit\",\"KHR_texture_transform\"]"},
    };
    for (size_t k = 0; k < sizeof(accepted) / sizeof(accepted[0]); k++) {
        char *doc = asset_doc(accepted[k].asset, accepted[k].extra);
        expect_imports(accepted[k].what, doc);
        free(doc);
    }
    expect_refused("empty", "", TW_ERR_FORMAT, "JSON: is empty");
    expect_refused("an array", " [1]", TW_ERR_FORMAT,
                   "JSON: the document is not a JSON object (it starts with '[')");
    expect_refused("no asset", "{}", TW_ERR_FORMAT,
                   "asset: is missing or not an object (it gives the glTF version)");

    /* Accessor data aligned to its component size (glTF 2.0 §3.6.2.4). */
    float data[16] = {0};
    memcpy(data, unit_triangle, sizeof(unit_triangle));
    char *doc = buffer_doc(data, 40, "\"bufferViews\":[{\"buffer\":0,\"byteLength\":40}],"
                           "\"accessors\":[{\"bufferView\":0,\"byteOffset\":2,"
                           "\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"}],"
                           "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                           "\"nodes\":[{\"mesh\":0}]");
    expect_refused("misaligned accessor", doc, TW_ERR_FORMAT,
                   "accessors[0].byteOffset: 2 puts its data at byte 2 of buffers[0], not a "
                   "multiple of 4 (its component type, FLOAT, is aligned to its size)");
    free(doc);

    /* Sparse indices strictly increase. */
    uint8_t sparse[64] = {0};
    memcpy(sparse, unit_triangle, 36);
    sparse[36] = 1;
    sparse[37] = 1;
    memcpy(sparse + 40, unit_triangle, 24);
    doc = buffer_doc(sparse, sizeof(sparse),
                     "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36},"
                     "{\"buffer\":0,\"byteOffset\":36,\"byteLength\":2},"
                     "{\"buffer\":0,\"byteOffset\":40,\"byteLength\":24}],"
                     "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                     "\"type\":\"VEC3\",\"sparse\":{\"count\":2,\"indices\":{\"bufferView\":1,"
                     "\"componentType\":5121},\"values\":{\"bufferView\":2}}}],"
                     "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                     "\"nodes\":[{\"mesh\":0}]");
    expect_refused("sparse indices", doc, TW_ERR_FORMAT,
                   "accessors[0].sparse.indices[1]: 1 follows 1; sparse indices must strictly "
                   "increase");
    free(doc);

    /* 255 in UNSIGNED_BYTE indices is primitive restart, forbidden in glTF,
     * though below the vertex count (300 zero positions). */
    const uint8_t restart[4] = {0, 1, 255, 0};
    doc = buffer_doc(restart, sizeof(restart),
                     "\"bufferViews\":[{\"buffer\":0,\"byteLength\":3}],"
                     "\"accessors\":[{\"componentType\":5126,\"count\":300,\"type\":\"VEC3\"},"
                     "{\"bufferView\":0,\"componentType\":5121,\"count\":3,\"type\":\"SCALAR\"}],"
                     "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},"
                     "\"indices\":1}]}],\"nodes\":[{\"mesh\":0}]");
    expect_refused("primitive restart", doc, TW_ERR_FORMAT,
                   "meshes[0].primitives[0].indices: accessors[1] element 2 is 255, the largest "
                   "UNSIGNED_BYTE, which glTF reserves (primitive restart)");
    free(doc);
}

/* ---- cost bounded by the input: accessors and conversion ----------------------------- */

/* 300000 UNSIGNED_INT indices 0, 1, 2, ... (1.2 MB) under many accessors. */
static char *indices_doc(uint32_t accessors, uint32_t primitives, bool shared)
{
    const uint32_t count = 300000;
    uint32_t *ix = malloc(4 * (size_t)count + 36);
    if (!ix)
        exit(3);
    memcpy(ix, unit_triangle, 36);
    for (uint32_t k = 0; k < count; k++)
        ix[9 + k] = k % 3;
    size_t cap = 256 + 128 * (size_t)(accessors + primitives), n = 0;
    char *members = malloc(cap);
    if (!members)
        exit(3);
    n += (size_t)snprintf(members, cap,
                          "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36},"
                          "{\"buffer\":0,\"byteOffset\":36,\"byteLength\":%u}],"
                          "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                          "\"type\":\"VEC3\"}",
                          4 * count);
    for (uint32_t k = 0; k < accessors; k++)
        n += (size_t)snprintf(members + n, cap - n,
                              ",{\"bufferView\":1,\"componentType\":5125,\"count\":%u,"
                              "\"type\":\"SCALAR\"}",
                              count);
    n += (size_t)snprintf(members + n, cap - n,
                          "],\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]},"
                          "{\"primitives\":[");
    for (uint32_t k = 0; k < primitives; k++)
        n += (size_t)snprintf(members + n, cap - n,
                              "%s{\"attributes\":{\"POSITION\":0},\"indices\":%u}", k ? "," : "",
                              shared ? 1 : 1 + k % accessors);
    snprintf(members + n, cap - n, "]}],\"nodes\":[{\"mesh\":0}]");
    char *doc = buffer_doc(ix, 4 * (size_t)count + 36, members);
    free(members);
    free(ix);
    return doc;
}

static void test_accessor_cost(void)
{
    /* 100 accessors over one 1.2 MB view, checked by 100 primitives (of a
     * mesh no node draws): 120 MB to check from a 1.6 MB file. */
    char *doc = indices_doc(100, 100, false);
    struct log_capture cap;
    struct tw_gltf_scene *s = NULL;
    int err = import_text(doc, "overlap.gltf", NULL, &cap, &s);
    CHECK_MSG(err == TW_ERR_LIMIT && strstr(cap.error, "overlap.gltf: accessors[") &&
                  strstr(cap.error, "accessors overlap"),
              "overlapping accessors: %d, %s", err, cap.error);
    tw_gltf_scene_destroy(s);
    free(doc);
    /* One accessor used by 1000 primitives is checked once. */
    doc = indices_doc(1, 1000, true);
    err = import_text(doc, "shared.gltf", NULL, &cap, &s);
    CHECK_MSG(err == 0, "one accessor, 1000 primitives: %s", cap.error);
    tw_gltf_scene_destroy(s);
    free(doc);

    /* 6 million positions without a buffer view (zeros) in a 300-byte
     * file: converting them would take 92 MiB. */
    const uint8_t none[4] = {0};
    doc = buffer_doc(none, sizeof(none),
                     "\"accessors\":[{\"componentType\":5126,\"count\":6000000,\"type\":"
                     "\"VEC3\"}],\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                     "\"nodes\":[{\"mesh\":0}]");
    expect_refused("6 million zero positions", doc, TW_ERR_LIMIT,
                   "meshes[0]: converting the scene's meshes would take 92 MiB, more than the "
                   "64 MiB allowed for");
    free(doc);
}

/* ---- cost bounded by the input: images -------------------------------------------------- */

struct bytes {
    uint8_t *p;
    size_t n, cap;
};

static void put(struct bytes *b, const void *data, size_t n)
{
    if (b->n + n > b->cap) {
        b->cap = 2 * (b->n + n) + 64;
        b->p = realloc(b->p, b->cap);
        if (!b->p)
            exit(3);
    }
    if (n)
        memcpy(b->p + b->n, data, n);
    b->n += n;
}

static void put32be(struct bytes *b, uint32_t v)
{
    const uint8_t x[4] = {(uint8_t)(v >> 24), (uint8_t)(v >> 16), (uint8_t)(v >> 8), (uint8_t)v};
    put(b, x, 4);
}

static uint32_t crc32_of(const uint8_t *p, size_t n)
{
    uint32_t crc = 0xffffffffu;
    for (size_t k = 0; k < n; k++) {
        crc ^= p[k];
        for (int bit = 0; bit < 8; bit++)
            crc = crc >> 1 ^ (0xedb88320u & (0u - (crc & 1u)));
    }
    return ~crc;
}

static void png_chunk(struct bytes *b, const char *type, const uint8_t *data, size_t n)
{
    put32be(b, (uint32_t)n);
    const size_t at = b->n;
    put(b, type, 4);
    put(b, data, n);
    put32be(b, crc32_of(b->p + at, n + 4));
}

/* A w x h PNG of 1-bit grey, every pixel black, its rows stored without
 * compression (w * h / 8 bytes or so); it decodes to 4 bytes a pixel. With
 * rows false, only its header and an empty IDAT: enough to read its size. */
static uint8_t *black_png(uint32_t w, uint32_t h, bool rows, size_t *size)
{
    static const uint8_t signature[8] = {137, 80, 78, 71, 13, 10, 26, 10};
    struct bytes b = {0}, z = {0};
    put(&b, signature, 8);
    uint8_t ihdr[13] = {0};
    for (int k = 0; k < 4; k++) {
        ihdr[k] = (uint8_t)(w >> (24 - 8 * k));
        ihdr[4 + k] = (uint8_t)(h >> (24 - 8 * k));
    }
    ihdr[8] = 1;    /* bit depth; colour type 0: grey */
    png_chunk(&b, "IHDR", ihdr, sizeof(ihdr));
    if (rows) {
        static const uint8_t zlib_header[2] = {0x78, 0x01};
        put(&z, zlib_header, 2);
        const uint64_t raw = (uint64_t)h * (1 + (w + 7) / 8);
        static const uint8_t zeros[65535];
        for (uint64_t left = raw; left > 0;) {
            const uint32_t n = left > 65535 ? 65535 : (uint32_t)left;
            left -= n;
            const uint8_t block[5] = {left == 0, (uint8_t)n, (uint8_t)(n >> 8),
                                      (uint8_t)~n, (uint8_t)(~n >> 8)};
            put(&z, block, 5);
            put(&z, zeros, n);
        }
        /* Adler-32 of zeros: a = 1, b = the count. */
        put32be(&z, (uint32_t)(raw % 65521) << 16 | 1u);
    }
    png_chunk(&b, "IDAT", z.p, z.n);
    png_chunk(&b, "IEND", NULL, 0);
    free(z.p);
    *size = b.n;
    return b.p;
}

/* A document of n triangles, triangle k textured by material k, texture k,
 * images[k]; images_json holds the n images, views_json more buffer views
 * (after the two of the triangle), buffer1 a second buffer (NULL: none). */
static char *textured_doc(uint32_t n, const char *images_json, const char *views_json,
                          const uint8_t *buffer1, size_t buffer1_size)
{
    uint8_t tri[60];
    static const float uv[6] = {0, 0, 1, 0, 0, 1};
    memcpy(tri, unit_triangle, 36);
    memcpy(tri + 36, uv, 24);
    char b0[96];
    base64(tri, sizeof(tri), b0);
    char *b1 = NULL;
    if (buffer1) {
        b1 = malloc(4 * (buffer1_size / 3 + 1) + 1);
        if (!b1)
            exit(3);
        base64(buffer1, buffer1_size, b1);
    }
    struct bytes list = {0};
    for (int part = 0; part < 3; part++) {
        const char *open = part == 0 ? "\"textures\":[" : part == 1 ? "],\"materials\":["
                                                                    : "],\"meshes\":[{\"primitives\":[";
        put(&list, open, strlen(open));
        for (uint32_t k = 0; k < n; k++) {
            char item[160];
            if (part == 0)
                snprintf(item, sizeof(item), "%s{\"source\":%u}", k ? "," : "", k);
            else if (part == 1)
                snprintf(item, sizeof(item),
                         "%s{\"pbrMetallicRoughness\":{\"baseColorTexture\":{\"index\":%u}}}",
                         k ? "," : "", k);
            else
                snprintf(item, sizeof(item),
                         "%s{\"attributes\":{\"POSITION\":0,\"TEXCOORD_0\":1},\"material\":%u}",
                         k ? "," : "", k);
            put(&list, item, strlen(item));
        }
    }
    put(&list, "]}]", 4);
    char *second = b1 ? format(",{\"byteLength\":%zu,\"uri\":"
                               "\"data:application/octet-stream;base64,%s\"}",
                               buffer1_size, b1)
                      : format("%s", "");
    char *doc = format("{\"asset\":{\"version\":\"2.0\"},"
                       "\"buffers\":[{\"byteLength\":60,\"uri\":"
                       "\"data:application/octet-stream;base64,%s\"}%s],"
                       "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36},"
                       "{\"buffer\":0,\"byteOffset\":36,\"byteLength\":24}%s],"
                       "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                       "\"type\":\"VEC3\"},{\"bufferView\":1,\"componentType\":5126,"
                       "\"count\":3,\"type\":\"VEC2\"}],"
                       "\"images\":[%s],%s,\"nodes\":[{\"mesh\":0}]}",
                       b0, second, views_json, images_json, list.p);
    free(second);
    free(b1);
    free(list.p);
    return doc;
}

static void test_image_cost(void)
{
    /* 4096 x 4096 decodes to 64 MiB from 2 MB. */
    size_t png_size;
    uint8_t *png = black_png(4096, 4096, true, &png_size);
    struct log_capture cap;
    struct tw_gltf_scene *s = NULL;

    /* Five images over the same bytes (five buffer views of one range):
     * decoded once, 64 MiB of the 256 MiB an import may decode. */
    struct bytes v = {0}, im = {0};
    for (uint32_t k = 0; k < 5; k++) {
        char item[128];
        snprintf(item, sizeof(item), ",{\"buffer\":1,\"byteLength\":%zu}", png_size);
        put(&v, item, strlen(item));
        snprintf(item, sizeof(item), "%s{\"bufferView\":%u,\"mimeType\":\"image/png\"}",
                 k ? "," : "", 2 + k);
        put(&im, item, strlen(item));
    }
    put(&v, "", 1);
    put(&im, "", 1);
    char *doc = textured_doc(5, (char *)im.p, (char *)v.p, png, png_size);
    int err = import_text(doc, "shared-image.gltf", NULL, &cap, &s);
    CHECK_MSG(err == 0 && cap.warnings == 0 && s && s->primitive_count == 5,
              "one image five times: %d, %d warnings, \"%s\"", err, cap.warnings, cap.warning);
    tw_gltf_scene_destroy(s);
    free(doc);
    free(v.p);

    /* Five copies at five places of the buffer: five images, the fifth
     * beyond the 256 MiB an import may decode (kept as its base colour). */
    uint8_t *copies = malloc(5 * png_size);
    if (!copies)
        exit(3);
    v = (struct bytes){0};
    for (uint32_t k = 0; k < 5; k++) {
        memcpy(copies + k * png_size, png, png_size);
        char item[128];
        snprintf(item, sizeof(item), ",{\"buffer\":1,\"byteOffset\":%zu,\"byteLength\":%zu}",
                 k * png_size, png_size);
        put(&v, item, strlen(item));
    }
    put(&v, "", 1);
    doc = textured_doc(5, (char *)im.p, (char *)v.p, copies, 5 * png_size);
    err = import_text(doc, "five-images.gltf", NULL, &cap, &s);
    CHECK_MSG(err == 0 && cap.warnings == 1 &&
                  strcmp(cap.warning, "five-images.gltf: images[4] (bufferViews[6]): a 4096 x "
                                      "4096 PNG would decode to 64 MiB, and the images decoded "
                                      "before it hold 256 MiB: more than the limit of 256 MiB "
                                      "per import; its materials keep their base colour "
                                      "factor") == 0,
              "five images: %d, %d warnings, \"%s\"", err, cap.warnings, cap.warning);
    tw_gltf_scene_destroy(s);
    free(doc);
    free(v.p);
    free(copies);
    free(im.p);

    /* A 200-byte PNG whose header says 32768 x 32768: refused by its
     * header, nothing decoded. */
    size_t header_size;
    uint8_t *header = black_png(32768, 32768, false, &header_size);
    char *b64 = malloc(4 * (header_size / 3 + 1) + 1);
    if (!b64)
        exit(3);
    base64(header, header_size, b64);
    char *one = format("{\"uri\":\"data:image/png;base64,%s\"}", b64);
    doc = textured_doc(1, one, "", NULL, 0);
    err = import_text(doc, "huge-image.gltf", NULL, &cap, &s);
    CHECK_MSG(err == 0 && cap.warnings == 1 &&
                  strcmp(cap.warning, "huge-image.gltf: images[0] (a data: URI): a 32768 x 32768 "
                                      "PNG would decode to 4.0 GiB, more than the limit of 64 "
                                      "MiB per image; its materials keep their base colour "
                                      "factor") == 0,
              "huge image: %d, \"%s\"", err, cap.warning);
    tw_gltf_scene_destroy(s);
    free(doc);
    free(one);
    free(b64);
    free(header);

    /* Twelve unusable images: eight warnings, then one line counting the
     * rest. */
    struct bytes bad = {0};
    for (uint32_t k = 0; k < 12; k++) {
        char text[32], enc[64], item[128];
        snprintf(text, sizeof(text), "not a PNG, number %02u", k);
        base64((const uint8_t *)text, strlen(text), enc);
        snprintf(item, sizeof(item), "%s{\"uri\":\"data:image/png;base64,%s\"}", k ? "," : "",
                 enc);
        put(&bad, item, strlen(item));
    }
    put(&bad, "", 1);
    doc = textured_doc(12, (char *)bad.p, "", NULL, 0);
    err = import_text(doc, "twelve.gltf", NULL, &cap, &s);
    CHECK_MSG(err == 0 && cap.warnings == 9 &&
                  strcmp(cap.warning, "twelve.gltf: 4 more warnings about textures and colours "
                                      "not shown") == 0,
              "twelve bad images: %d, %d warnings, last \"%s\"", err, cap.warnings, cap.warning);
    tw_gltf_scene_destroy(s);
    free(doc);
    free(bad.p);
    free(png);
}

/* ---- manifests: what many files cost together ------------------------------------------ */

static int load_manifest_in(const char *folder, const char *text,
                            const struct tw_manifest_settings *settings, struct log_capture *cap,
                            struct tw_tileset **ts)
{
    char *path = format("%s/test.json", folder);
    write_file(path, text, strlen(text));
    const struct tw_log log = new_log(cap);
    *ts = NULL;
    const int err = tw_tilesets_load_manifest(path, settings, &log, ts);
    free(path);
    return err;
}

/* A manifest of n prototypes "p<k>", prototype k placing the files that
 * file_of(k, o) names, objects_per of them. */
static char *manifest_of(uint32_t n, uint32_t objects_per, const char *name_fmt)
{
    struct bytes b = {0};
    const char *head = "{\"footprint\": [40, 40], \"prototypes\": [";
    put(&b, head, strlen(head));
    for (uint32_t k = 0; k < n; k++) {
        char item[160];
        snprintf(item, sizeof(item), "%s{\"name\": \"p%u\", \"objects\": [", k ? "," : "", k);
        put(&b, item, strlen(item));
        for (uint32_t o = 0; o < objects_per; o++) {
            char file[64];
            snprintf(file, sizeof(file), name_fmt, k, o);
            snprintf(item, sizeof(item), "%s{\"gltf\": \"%s\"}", o ? "," : "", file);
            put(&b, item, strlen(item));
        }
        put(&b, "]}", 2);
    }
    put(&b, "]}", 3);
    return (char *)b.p;
}

static void test_manifest_cost(void)
{
    char *folder = in_tmp("mc");
    mkdir(folder, 0755);
    struct log_capture cap;
    struct tw_tileset *ts = NULL;

    /* Five files naming one external 4096 x 4096 PNG (64 MiB decoded): read
     * and decoded once for the manifest, not five times (320 MiB, beyond
     * the 256 MiB a manifest's imports may decode together). */
    size_t png_size;
    uint8_t *png = black_png(4096, 4096, true, &png_size);
    char *path = format("%s/big.png", folder);
    write_file(path, png, png_size);
    free(path);
    free(png);
    for (int k = 0; k < 5; k++) {
        char *doc = textured_doc(1, "{\"uri\":\"big.png\"}", "", NULL, 0);
        path = format("%s/g%d.gltf", folder, k);
        write_file(path, doc, strlen(doc));
        free(path);
        free(doc);
    }
    char *text = manifest_of(5, 1, "g%u.gltf");
    int err = load_manifest_in(folder, text, NULL, &cap, &ts);
    CHECK_MSG(err == 0 && ts && cap.warnings == 0,
              "one PNG named by five files: %d, \"%s\", %d warnings, \"%s\"", err, cap.error,
              cap.warnings, cap.warning);
    tw_tileset_destroy(ts);
    free(text);

    /* Six files each reading a 900 KiB buffer file, files of at most 1 MiB:
     * the manifest's imports may read 4 MiB together. */
    char *bin = format("%s/big.bin", folder);
    char *zeros = calloc(1, 900 << 10);
    if (!zeros)
        exit(3);
    memcpy(zeros, unit_triangle, sizeof(unit_triangle));
    write_file(bin, zeros, 900 << 10);
    free(zeros);
    free(bin);
    for (int k = 0; k < 6; k++) {
        char *doc = format("{\"asset\":{\"version\":\"2.0\"},"
                           "\"buffers\":[{\"byteLength\":%d,\"uri\":\"big.bin\"}],"
                           "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
                           "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                           "\"type\":\"VEC3\"}],"
                           "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                           "\"nodes\":[{\"mesh\":0}]}",
                           900 << 10);
        path = format("%s/b%d.gltf", folder, k);
        write_file(path, doc, strlen(doc));
        free(path);
        free(doc);
    }
    struct tw_manifest_settings settings = {0};
    settings.gltf.max_file_bytes = 1 << 20;
    text = manifest_of(6, 1, "b%u.gltf");
    err = load_manifest_in(folder, text, &settings, &cap, &ts);
    CHECK_MSG(err == TW_ERR_LIMIT && !ts &&
                  strstr(cap.error, "test.json: prototypes[4].objects[0].gltf: b4.gltf: buffers: "
                                    "buffer file \"big.bin\" is too large: with the files read "
                                    "before it for the same manifest it exceeds the limit of "
                                    "4194304 bytes"),
              "six files reading 900 KiB: %d, \"%s\"", err, cap.error);
    free(text);

    /* Triangles placed: a file drawing 40 triangles (one mesh, 40 nodes),
     * with a limit of 100 a prototype, 1000 a tileset. */
    char *nodes = format("%s", "");
    for (int k = 0; k < 40; k++) {
        char *more = format("%s%s{\"mesh\":0,\"translation\":[%d,0,0]}", nodes, k ? "," : "",
                            k % 20);
        free(nodes);
        nodes = more;
    }
    char *list = format("[%s]", nodes);
    char *doc = triangle_doc(unit_triangle, list, NULL);
    path = format("%s/t40.gltf", folder);
    write_file(path, doc, strlen(doc));
    free(path);
    free(doc);
    free(list);
    free(nodes);
    settings = (struct tw_manifest_settings){0};
    settings.gltf.max_triangles = 100;
    text = manifest_of(1, 3, "t40.gltf");
    err = load_manifest_in(folder, text, &settings, &cap, &ts);
    CHECK_MSG(err == TW_ERR_LIMIT &&
                  strstr(cap.error, "test.json: prototypes[0].objects[2].gltf: placing "
                                    "\"t40.gltf\" (40 triangles) here makes the prototype draw "
                                    "120 triangles, more than the limit of 100"),
              "a prototype of 120 triangles: %d, \"%s\"", err, cap.error);
    free(text);
    text = manifest_of(13, 2, "t40.gltf");
    err = load_manifest_in(folder, text, &settings, &cap, &ts);
    CHECK_MSG(err == TW_ERR_LIMIT &&
                  strstr(cap.error, "test.json: prototypes[12].objects[1].gltf: placing "
                                    "\"t40.gltf\" (40 triangles) here makes the tileset's "
                                    "prototypes draw 1040 triangles together, more than the "
                                    "limit of 1000"),
              "a tileset of 1040 triangles: %d, \"%s\"", err, cap.error);
    free(text);

    /* A prototype whose every triangle has no area draws nothing: said so,
     * not "invalid argument". */
    static const float flat[9] = {0, 0, 0, 1, 0, 0, 2, 0, 0};
    doc = triangle_doc(flat, "[{\"mesh\":0}]", NULL);
    path = format("%s/flat.gltf", folder);
    write_file(path, doc, strlen(doc));
    free(path);
    free(doc);
    err = load_manifest_in(folder,
                           "{\"footprint\": [10, 10], \"prototypes\": [{\"name\": \"ok\", "
                           "\"gltf\": \"t40.gltf\"}, {\"name\": \"flat\", \"gltf\": "
                           "\"flat.gltf\"}]}",
                           NULL, &cap, &ts);
    CHECK_MSG(err == TW_ERR_FORMAT &&
                  strstr(cap.error, "test.json: prototypes[1]: every triangle of \"flat\" has no "
                                    "area (collinear or coincident corners): it would draw "
                                    "nothing"),
              "a prototype without area: %d, \"%s\"", err, cap.error);

    /* A manifest that does not exist. */
    char *missing = format("%s/missing.json", folder);
    const struct tw_log log = new_log(&cap);
    err = tw_tilesets_load_manifest(missing, NULL, &log, &ts);
    char *want = format("%s: no such file", missing);
    CHECK_MSG(err == TW_ERR_IO && strcmp(cap.error, want) == 0, "missing manifest: \"%s\"",
              cap.error);
    free(want);
    free(missing);
    free(folder);
}

/* ---- main ---------------------------------------------------------------------------- */

static void remove_tree(const char *path)
{
    struct stat st;
    if (lstat(path, &st) != 0)
        return;
    if (S_ISDIR(st.st_mode)) {
        char *cmd = format("rm -rf '%s'", path);
        if (system(cmd) != 0)
            fprintf(stderr, "test-hostile: cannot remove %s\n", path);
        free(cmd);
        return;
    }
    unlink(path);
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: test-hostile SOURCE_ROOT\n");
        return 2;
    }
    source_root = argv[1];
    snprintf(tmp, sizeof(tmp), "/tmp/tw-test-hostile-XXXXXX");
    if (!mkdtemp(tmp)) {
        fprintf(stderr, "test-hostile: cannot make a temporary folder: %s\n", strerror(errno));
        return 1;
    }
    test_coordinates();
    test_quantized();
    test_valid_files();
    test_escapes();
    test_manifests();
    test_confined();
    test_import_cost();
    test_spec();
    test_accessor_cost();
    test_image_cost();
    test_manifest_cost();
    remove_tree(tmp);
    return check_summary("test-hostile");
}
