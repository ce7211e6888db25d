/* Hostile and broken input for glTF import, manifests and confined paths
 * (issue 11): no crash, no hang, bounded cost, one message per bad input
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
    const int err = tw_tilesets_load_manifest(path, &log, ts);
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
    int err = tw_tilesets_load_manifest(fifo, &log, &ts);
    watchdog_disarm();
    char *want = format("%s: is not a regular file (a FIFO)", fifo);
    CHECK_MSG(err == TW_ERR_IO && ts == NULL && strcmp(cap.error, want) == 0, "FIFO manifest: %s",
              cap.error);
    free(want);
    unlink(fifo);
    free(fifo);
    /* ... and so is /dev/zero. */
    err = tw_tilesets_load_manifest("/dev/zero", &log, &ts);
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
    remove_tree(tmp);
    return check_summary("test-hostile");
}
