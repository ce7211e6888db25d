/* Tests of glTF import and tileset manifests (tilesets.h).
 *
 * usage: test-gltf SHARED_DIR SOURCE_ROOT
 *
 * Every .gltf/.glb under SHARED_DIR/assets/bad either imports or is refused
 * with one message naming the file; the valid models under
 * SHARED_DIR/assets/models import with the triangle counts and bounds that
 * SHARED_DIR/assets/MANIFEST.md lists; synthetic documents probe each check;
 * manifests are loaded and refused in a temporary folder; the manifests
 * shipped in SOURCE_ROOT/tilesets load. Prints a table of the bad files,
 * imported vs refused, reasons grouped. Plain C: main returns 0 when every
 * check holds, 77 (meson's skip) when SHARED_DIR is missing. */
#include "tileworld/tilesets.h"

#include <dirent.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "tests/base64.h"
#include "tests/captured-log.h"
#include "tests/check.h"
#include "tiles/tiles-internal.h"
#include "tilesets/tilesets-private.h"

#if defined(__SANITIZE_ADDRESS__)
#define UNDER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define UNDER_ASAN 1
#endif
#endif

static const char *shared_dir;
static const char *source_root;

/* ---- names ------------------------------------------------------------------------- */

static char *join(const char *a, const char *b)
{
    const size_t n = strlen(a) + strlen(b) + 2;
    char *s = malloc(n);
    if (!s) {
        fprintf(stderr, "test-gltf: out of memory\n");
        exit(1);
    }
    snprintf(s, n, "%s/%s", a, b);
    return s;
}

static bool ends_with(const char *s, const char *suffix)
{
    const size_t n = strlen(s), m = strlen(suffix);
    return n >= m && strcmp(s + n - m, suffix) == 0;
}

static bool starts_with(const char *s, const char *prefix)
{
    return strncmp(s, prefix, strlen(prefix)) == 0;
}

/* ---- the bad files ------------------------------------------------------------------- */

struct reason_group {
    char reason[96];
    unsigned count;
    char example[160];
};

struct bad_table {
    unsigned imported, refused;
    struct reason_group groups[256];
    unsigned group_count;
    char imported_names[4096];
};

/* A reason without its particulars: numbers become #, quoted text "...". */
static void reason_key(const char *msg, char *out, size_t size)
{
    size_t n = 0;
    for (const char *p = msg; *p && n + 4 < size; p++) {
        if (*p >= '0' && *p <= '9') {
            while (p[1] >= '0' && p[1] <= '9')
                p++;
            out[n++] = '#';
        } else if (*p == '"') {
            const char *close = strchr(p + 1, '"');
            if (!close)
                break;
            memcpy(out + n, "\"\"", 2);
            n += 2;
            p = close;
        } else {
            out[n++] = *p;
        }
    }
    out[n] = '\0';
}

static void add_reason(struct bad_table *t, const char *path, const char *msg)
{
    /* msg is "<path>: <element>: <reason>": group by what follows the path. */
    const char *rest = starts_with(msg, path) ? msg + strlen(path) + 2 : msg;
    char key[96];
    reason_key(rest, key, sizeof(key));
    for (unsigned k = 0; k < t->group_count; k++) {
        if (strcmp(t->groups[k].reason, key) == 0) {
            t->groups[k].count++;
            return;
        }
    }
    if (t->group_count < sizeof(t->groups) / sizeof(t->groups[0])) {
        struct reason_group *g = &t->groups[t->group_count++];
        snprintf(g->reason, sizeof(g->reason), "%s", key);
        g->count = 1;
        snprintf(g->example, sizeof(g->example), "%s", path + strlen(shared_dir) + 1);
    }
}

static void import_bad_file(struct bad_table *t, const char *path)
{
    struct captured_log cap = {"", 0};
    const struct tw_log log = {capture, &cap};
    struct tw_gltf_scene *scene = NULL;
    const int err = tw_gltf_import(path, NULL, &log, &scene);
    if (err == 0) {
        CHECK_MSG(scene && scene->triangle_count > 0 && cap.errors == 0, "%s", path);
        t->imported++;
        const size_t n = strlen(t->imported_names);
        snprintf(t->imported_names + n, sizeof(t->imported_names) - n, "  %s (%llu triangles)\n",
                 path + strlen(shared_dir) + 1, (unsigned long long)scene->triangle_count);
    } else {
        CHECK_MSG(scene == NULL, "%s", path);
        CHECK_MSG(cap.errors == 1, "%s: %d error lines", path, cap.errors);
        CHECK_MSG(starts_with(cap.last, path), "%s: the message does not name the file: %s", path,
                  cap.last);
        CHECK_MSG(!strchr(cap.last, '\n'), "%s: the message has several lines", path);
        t->refused++;
        add_reason(t, path, cap.last);
    }
    tw_gltf_scene_destroy(scene);
}

static void walk_bad(struct bad_table *t, const char *dir)
{
    struct dirent **entries = NULL;
    const int n = scandir(dir, &entries, NULL, alphasort);
    CHECK_MSG(n >= 0, "cannot list %s", dir);
    for (int k = 0; k < n; k++) {
        const char *name = entries[k]->d_name;
        if (name[0] != '.') {
            char *path = join(dir, name);
            struct stat st;
            if (stat(path, &st) == 0 && S_ISDIR(st.st_mode))
                walk_bad(t, path);
            else if (ends_with(name, ".gltf") || ends_with(name, ".glb"))
                import_bad_file(t, path);
            free(path);
        }
        free(entries[k]);
    }
    free(entries);
}

static int compare_groups(const void *a, const void *b)
{
    const struct reason_group *x = a, *y = b;
    if (x->count != y->count)
        return x->count < y->count ? 1 : -1;
    return strcmp(x->reason, y->reason);
}

/* Imports path and returns the error, with the message in cap. */
static int import_one(const char *relative, struct captured_log *cap,
                      struct tw_gltf_scene **scene)
{
    char *path = join(shared_dir, relative);
    const struct tw_log log = {capture, cap};
    cap->errors = 0;
    cap->last[0] = '\0';
    const int err = tw_gltf_import(path, NULL, &log, scene);
    free(path);
    return err;
}

static void test_bad_files(void)
{
    char *bad = join(shared_dir, "assets/bad");
    struct stat st;
    if (stat(bad, &st) != 0 || !S_ISDIR(st.st_mode)) {
        fprintf(stderr, "test-gltf: %s is missing: the bad-input corpus is required\n", bad);
        exit(1);
    }
    struct bad_table *t = calloc(1, sizeof(*t));
    if (!t)
        exit(1);
    walk_bad(t, bad);
    CHECK_MSG(t->imported + t->refused > 250, "only %u files found", t->imported + t->refused);
    qsort(t->groups, t->group_count, sizeof(t->groups[0]), compare_groups);
    printf("\nbad glTF files (%s): %u files, %u imported, %u refused\n", bad,
           t->imported + t->refused, t->imported, t->refused);
    printf("refused, by reason:\n");
    for (unsigned k = 0; k < t->group_count; k++)
        printf("  %4u  %-90s  (e.g. %s)\n", t->groups[k].count, t->groups[k].reason,
               t->groups[k].example);
    printf("imported:\n%s\n", t->imported_names);
    free(t);
    free(bad);

    /* Specific files. */
    struct captured_log cap;
    struct tw_gltf_scene *scene = NULL;
    int err = import_one("assets/bad/tinygltf/tests/issue-416.gltf", &cap, &scene);
    CHECK_MSG(err != 0 && scene == NULL && cap.errors == 1, "issue-416 imported");
    err = import_one("assets/bad/gltf-validator/node/node_loop.gltf", &cap, &scene);
    CHECK_MSG(err == TW_ERR_FORMAT && strstr(cap.last, "cycle"), "node_loop: %s", cap.last);
    err = import_one("assets/bad/gltf-validator/node/node_loop_scene.gltf", &cap, &scene);
    CHECK_MSG(err == TW_ERR_FORMAT && strstr(cap.last, "cycle"), "node_loop_scene: %s", cap.last);
    err = import_one("assets/bad/gltf-validator/mesh_data/index_buffer_oob.gltf", &cap, &scene);
    CHECK_MSG(err == TW_ERR_FORMAT && strstr(cap.last, "indices") &&
                  strstr(cap.last, "not below the vertex count"),
              "index_buffer_oob: %s", cap.last);
    err = import_one("assets/bad/gltf-validator/node/unresolved_child_node.gltf", &cap, &scene);
    CHECK_MSG(err == TW_ERR_FORMAT && strstr(cap.last, "children[0]") &&
                  strstr(cap.last, "is not a node"),
              "unresolved_child_node: %s", cap.last);
    err = import_one("assets/bad/gltf-validator/node/node_parent_override.gltf", &cap, &scene);
    CHECK_MSG(err == TW_ERR_FORMAT && strstr(cap.last, "one parent"), "node_parent_override: %s",
              cap.last);
    err = import_one("assets/bad/gltf-validator/mesh/unresolved_positions.gltf", &cap, &scene);
    CHECK_MSG(err == TW_ERR_FORMAT && strstr(cap.last, "POSITION"), "unresolved_positions: %s",
              cap.last);
    err = import_one("assets/bad/tinygltf/models/BoundsChecking/invalid-primitive-indices.gltf",
                     &cap, &scene);
    CHECK_MSG(err != 0 && cap.errors == 1, "invalid-primitive-indices imported");
    tw_gltf_scene_destroy(scene);
}

/* ---- the valid models ------------------------------------------------------------- */

static void test_valid_models(void)
{
    char *manifest = join(shared_dir, "assets/MANIFEST.md");
    FILE *f = fopen(manifest, "r");
    CHECK_MSG(f != NULL, "cannot open %s", manifest);
    if (!f) {
        free(manifest);
        return;
    }
    char line[2048];
    unsigned models = 0;
    printf("valid models:\n");
    while (fgets(line, sizeof(line), f)) {
        /* | models/x.glb | bytes | tris | [a, b, c]..[d, e, f] | ok | ... */
        char file[512];
        unsigned long long bytes, tris;
        float lo[3], hi[3];
        if (sscanf(line, "| %511s | %llu | %llu | [%f, %f, %f]..[%f, %f, %f] |", file, &bytes,
                   &tris, &lo[0], &lo[1], &lo[2], &hi[0], &hi[1], &hi[2]) != 9 ||
            !starts_with(file, "models/"))
            continue;
        char relative[600];
        snprintf(relative, sizeof(relative), "assets/%s", file);
        struct captured_log cap;
        struct tw_gltf_scene *scene = NULL;
        const int err = import_one(relative, &cap, &scene);
        CHECK_MSG(err == 0, "%s: %s", file, cap.last);
        if (err == 0) {
            CHECK_MSG(scene->triangle_count == tris, "%s: %llu triangles, MANIFEST.md says %llu",
                      file, (unsigned long long)scene->triangle_count, tris);
            for (int k = 0; k < 3; k++)
                CHECK_MSG(fabsf(scene->bounds.min[k] - lo[k]) < 0.011f &&
                              fabsf(scene->bounds.max[k] - hi[k]) < 0.011f,
                          "%s: bounds axis %d: [%g, %g], MANIFEST.md says [%g, %g]", file, k,
                          scene->bounds.min[k], scene->bounds.max[k], lo[k], hi[k]);
            printf("  %-72s %8llu triangles, %u meshes, %u instances\n", file,
                   (unsigned long long)scene->triangle_count, scene->mesh_count,
                   scene->instance_count);
        }
        tw_gltf_scene_destroy(scene);
        models++;
    }
    fclose(f);
    free(manifest);
    CHECK_MSG(models >= 30, "only %u models listed in MANIFEST.md", models);
}

/* ---- synthetic documents ------------------------------------------------------------- */

/* Five vertices and six 16-bit indices (two triangles), 72 bytes. */
static char data_uri[256];

static void make_data(const float *positions)
{
    static const float square[15] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0, 2, 0, 0};
    static const uint16_t indices[6] = {0, 1, 2, 1, 3, 2};
    uint8_t bytes[72];
    memcpy(bytes, positions ? positions : square, 60);
    memcpy(bytes + 60, indices, 12);
    strcpy(data_uri, "data:application/octet-stream;base64,");
    base64(bytes, sizeof(bytes), data_uri + strlen(data_uri));
}

static const char default_accessors[] =
    "[{\"bufferView\":0,\"componentType\":5126,\"count\":5,\"type\":\"VEC3\"},"
    "{\"bufferView\":1,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]";
static const char default_primitive[] = "{\"attributes\":{\"POSITION\":0},\"indices\":1}";
static const char default_nodes[] = "[{\"mesh\":0}]";
static const char default_scenes[] = "\"scenes\":[{\"nodes\":[0]}],\"scene\":0";

/* Imports a document built from the parts (NULL: the defaults above);
 * extra goes at the top level. */
static int import_doc(const char *accessors, const char *primitive, const char *nodes,
                      const char *scenes, const char *extra,
                      const struct tw_gltf_settings *settings, struct captured_log *cap,
                      struct tw_gltf_scene **scene)
{
    if (!data_uri[0])
        make_data(NULL);
    char doc[8192];
    snprintf(doc, sizeof(doc),
             "{\"asset\":{\"version\":\"2.0\"},"
             "\"buffers\":[{\"byteLength\":72,\"uri\":\"%s\"}],"
             "\"bufferViews\":[{\"buffer\":0,\"byteLength\":60},"
             "{\"buffer\":0,\"byteOffset\":60,\"byteLength\":12}],"
             "\"accessors\":%s,\"meshes\":[{\"primitives\":[%s]}],\"nodes\":%s%s%s%s%s}",
             data_uri, accessors ? accessors : default_accessors,
             primitive ? primitive : default_primitive, nodes ? nodes : default_nodes,
             scenes && !scenes[0] ? "" : ",", scenes ? scenes : default_scenes,
             extra ? "," : "", extra ? extra : "");
    const struct tw_log log = {capture, cap};
    cap->errors = 0;
    cap->last[0] = '\0';
    *scene = NULL;
    return tw_gltf_import_memory(doc, strlen(doc), "synthetic.gltf", NULL, settings, &log, scene);
}

/* Expects the document to be refused with a message containing want. */
static void expect_refused(const char *what, int want_err, const char *want, const char *accessors,
                           const char *primitive, const char *nodes, const char *scenes,
                           const char *extra)
{
    struct captured_log cap;
    struct tw_gltf_scene *scene = NULL;
    const int err = import_doc(accessors, primitive, nodes, scenes, extra, NULL, &cap, &scene);
    CHECK_MSG(err == want_err && scene == NULL && cap.errors == 1 && strstr(cap.last, want) &&
                  starts_with(cap.last, "synthetic.gltf: "),
              "%s: error %d, message \"%s\" (expected %d and \"%s\")", what, err, cap.last, want_err,
              want);
    tw_gltf_scene_destroy(scene);
}

static bool near(float a, float b)
{
    return fabsf(a - b) < 1e-4f;
}

static void test_synthetic(void)
{
    struct captured_log cap;
    struct tw_gltf_scene *s = NULL;

    /* One mesh, two nodes: shared, not copied. */
    int err = import_doc(NULL, NULL, "[{\"mesh\":0},{\"mesh\":0,\"translation\":[5,0,0]}]",
                         "\"scenes\":[{\"nodes\":[0,1]}]", NULL, NULL, &cap, &s);
    CHECK_MSG(err == 0, "shared mesh: %s", cap.last);
    if (!err) {
        CHECK_MSG(s->mesh_count == 1 && s->primitive_count == 1 && s->instance_count == 2,
                  "%u meshes, %u instances", s->mesh_count, s->instance_count);
        CHECK_MSG(s->triangle_count == 4 && s->unique_triangles == 2, "%llu drawn",
                  (unsigned long long)s->triangle_count);
        CHECK_MSG(near(s->bounds.max[0], 7.0f) && near(s->bounds.min[0], 0.0f), "bounds x %g..%g",
                  s->bounds.min[0], s->bounds.max[0]);
        CHECK_MSG(s->material_count == 1 && near(s->materials[0].base_color[0], 0.6f),
                  "default grey");
        CHECK_MSG(s->primitives[0].normals == NULL, "no normals in the file");
        /* What `tileworld import` summarises: the counts over the meshes. */
        CHECK_MSG(s->vertex_count == s->primitives[0].vertex_count, "%llu vertices",
                  (unsigned long long)s->vertex_count);
    }
    tw_gltf_scene_destroy(s);

    /* Strips and fans: the triangles they make, and the order of the
     * indices at[] they are made of. */
    static const struct {
        const char *what, *primitive;
        uint64_t triangles;
        unsigned checked;   /* how many of at[] and want[] */
        unsigned at[6];
        uint32_t want[6];
    } modes[] = {
        /* Without indices: 5 vertices, 3 triangles. */
        {"strip", "{\"attributes\":{\"POSITION\":0},\"mode\":5}", 3, 6, {0, 1, 2, 3, 4, 5},
         {0, 1, 2, 2, 1, 3}},
        {"fan", "{\"attributes\":{\"POSITION\":0},\"mode\":6}", 3, 6, {0, 1, 2, 6, 7, 8},
         {1, 2, 0, 3, 4, 0}},
        /* Indexed strip: 6 indices, 4 triangles. */
        {"indexed strip", "{\"attributes\":{\"POSITION\":0},\"indices\":1,\"mode\":5}", 4, 0,
         {0}, {0}},
    };
    for (size_t m = 0; m < sizeof(modes) / sizeof(modes[0]); m++) {
        err = import_doc(NULL, modes[m].primitive, NULL, NULL, NULL, NULL, &cap, &s);
        CHECK_MSG(err == 0 && s->triangle_count == modes[m].triangles, "%s: %s", modes[m].what,
                  cap.last);
        if (!err && modes[m].checked) {
            const uint32_t *ix = s->primitives[0].indices;
            bool order = true;
            for (unsigned q = 0; q < modes[m].checked; q++)
                order &= ix[modes[m].at[q]] == modes[m].want[q];
            CHECK_MSG(order, "%s order: %u %u %u, %u %u %u", modes[m].what, ix[modes[m].at[0]],
                      ix[modes[m].at[1]], ix[modes[m].at[2]], ix[modes[m].at[3]],
                      ix[modes[m].at[4]], ix[modes[m].at[5]]);
        }
        tw_gltf_scene_destroy(s);
    }

    /* Transforms: a matrix, and a TRS hierarchy, and the bounds they give. */
    static const struct {
        const char *what, *nodes;
        float min[3], max[3];
    } transforms[] = {
        {"matrix", "[{\"mesh\":0,\"matrix\":[2,0,0,0, 0,2,0,0, 0,0,2,0, 1,2,3,1]}]", {1, 2, 3},
         {5, 4, 3}},
        {"hierarchy",
         "[{\"translation\":[10,0,0],\"rotation\":[0,0.70710678,0,0.70710678],"
         "\"children\":[1]},{\"mesh\":0,\"scale\":[2,2,2]}]",
         {10, 0, -4}, {10, 2, 0}},
    };
    for (size_t t = 0; t < sizeof(transforms) / sizeof(transforms[0]); t++) {
        err = import_doc(NULL, NULL, transforms[t].nodes, NULL, NULL, NULL, &cap, &s);
        CHECK_MSG(err == 0, "%s: %s", transforms[t].what, cap.last);
        if (!err) {
            bool bounds = true;
            for (int k = 0; k < 3; k++)
                bounds &= near(s->bounds.min[k], transforms[t].min[k]) &&
                          near(s->bounds.max[k], transforms[t].max[k]);
            CHECK_MSG(bounds, "%s bounds [%g %g %g]..[%g %g %g]", transforms[t].what,
                      s->bounds.min[0], s->bounds.min[1], s->bounds.min[2], s->bounds.max[0],
                      s->bounds.max[1], s->bounds.max[2]);
        }
        tw_gltf_scene_destroy(s);
    }

    /* No scene: every root node is drawn. */
    err = import_doc(NULL, NULL, "[{\"mesh\":0},{\"mesh\":0}]", "", NULL, NULL, &cap, &s);
    CHECK_MSG(err == 0 && s->instance_count == 2, "no scene: %s", cap.last);
    tw_gltf_scene_destroy(s);

    /* Limits. */
    const struct tw_gltf_settings one_triangle = {0, 1};
    err = import_doc(NULL, NULL, NULL, NULL, NULL, &one_triangle, &cap, &s);
    CHECK_MSG(err == TW_ERR_LIMIT && strstr(cap.last, "limit"), "triangle limit: %s", cap.last);
    tw_gltf_scene_destroy(s);
    const struct tw_gltf_settings small_file = {100, 0};
    err = import_doc(NULL, NULL, NULL, NULL, NULL, &small_file, &cap, &s);
    CHECK_MSG(err == TW_ERR_LIMIT && strstr(cap.last, "limit"), "file limit: %s", cap.last);
    tw_gltf_scene_destroy(s);

    /* Refusals, one check each. */
    static const struct {
        const char *what;
        int err;
        const char *want, *accessors, *primitive, *nodes, *scenes, *extra;
    } refused[] = {
        /* Points and lines are not drawn (skipped with a warning,
         * hostile.c tests the rest); alone, nothing is drawn. */
        {.what = "points", .err = TW_ERR_FORMAT,
         .want = "draws nothing",
         .primitive = "{\"attributes\":{\"POSITION\":0},\"mode\":0}"},
        {.what = "lines", .err = TW_ERR_FORMAT,
         .want = "draws nothing",
         .primitive = "{\"attributes\":{\"POSITION\":0},\"mode\":1}"},
        {.what = "unknown mode", .err = TW_ERR_FORMAT,
         .want = "mode: 9 is not a glTF primitive mode",
         .primitive = "{\"attributes\":{\"POSITION\":0},\"mode\":9}"},
        {.what = "not a multiple of 3", .err = TW_ERR_FORMAT,
         .want = "5 vertices is not a multiple of 3",
         .primitive = "{\"attributes\":{\"POSITION\":0}}"},
        {.what = "two parents", .err = TW_ERR_FORMAT,
         .want = "nodes[1].children[0]: nodes[2] is already a child of nodes[0]",
         .nodes = "[{\"children\":[2]},{\"children\":[2]},{\"mesh\":0}]",
         .scenes = "\"scenes\":[{\"nodes\":[0,1]}]"},
        {.what = "own child", .err = TW_ERR_FORMAT,
         .want = "nodes[0].children[0]: the node is its own child",
         .nodes = "[{\"mesh\":0,\"children\":[0]}]"},
        {.what = "cycle", .err = TW_ERR_FORMAT,
         .want = "(a cycle)",
         .nodes = "[{\"mesh\":0},{\"children\":[2]},{\"children\":[1]}]"},
        {.what = "dangling child", .err = TW_ERR_FORMAT,
         .want = "nodes[0].children[0]: 7 is not a node",
         .nodes = "[{\"mesh\":0,\"children\":[7]}]"},
        {.what = "dangling mesh", .err = TW_ERR_FORMAT,
         .want = "nodes[0].mesh: 3 is not a mesh",
         .nodes = "[{\"mesh\":3}]"},
        {.what = "dangling scene node", .err = TW_ERR_FORMAT,
         .want = "scenes[0].nodes[0]: 4 is not a node",
         .scenes = "\"scenes\":[{\"nodes\":[4]}]"},
        {.what = "child as root", .err = TW_ERR_FORMAT,
         .want = "is not a root",
         .nodes = "[{\"children\":[1]},{\"mesh\":0}]",
         .scenes = "\"scenes\":[{\"nodes\":[0,1]}]"},
        {.what = "short translation", .err = TW_ERR_FORMAT,
         .want = "nodes[0].translation: has 2 values",
         .nodes = "[{\"mesh\":0,\"translation\":[1,2]}]"},
        {.what = "zero rotation", .err = TW_ERR_FORMAT,
         .want = "is not a rotation",
         .nodes = "[{\"mesh\":0,\"rotation\":[0,0,0,0]}]"},
        {.what = "transform overflow", .err = TW_ERR_LIMIT,
         .want = "nodes[0].scale: 1e+30 is beyond +-1e+07",
         .nodes = "[{\"scale\":[1e30,1e30,1e30],\"children\":[1]},"
                  "{\"mesh\":0,\"scale\":[1e30,1e30,1e30]}]"},
        {.what = "accessor overrun", .err = TW_ERR_FORMAT,
         .want = "accessors[0]: 6 elements",
         .accessors = "[{\"bufferView\":0,\"componentType\":5126,\"count\":6,\"type\":\"VEC3\"},"
                      "{\"bufferView\":1,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]"},
        {.what = "offset overrun", .err = TW_ERR_FORMAT,
         .want = "overrun bufferViews[1]",
         .accessors = "[{\"bufferView\":0,\"componentType\":5126,\"count\":5,\"type\":\"VEC3\"},"
                      "{\"bufferView\":1,\"byteOffset\":4,\"componentType\":5123,\"count\":6,"
                      "\"type\":\"SCALAR\"}]"},
        {.what = "dangling buffer view", .err = TW_ERR_FORMAT,
         .want = "accessor[1] invalid bufferView",
         .accessors = "[{\"bufferView\":0,\"componentType\":5126,\"count\":5,\"type\":\"VEC3\"},"
                      "{\"bufferView\":9,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]"},
        {.what = "positions of ints", .err = TW_ERR_FORMAT,
         .want = "positions must be VEC3 of FLOAT",
         .accessors = "[{\"bufferView\":0,\"componentType\":5125,\"count\":5,\"type\":\"VEC3\"},"
                      "{\"bufferView\":1,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]"},
        {.what = "float indices", .err = TW_ERR_FORMAT,
         .want = "indices must be SCALAR",
         .accessors = "[{\"bufferView\":0,\"componentType\":5126,\"count\":5,\"type\":\"VEC3\"},"
                      "{\"bufferView\":0,\"componentType\":5126,\"count\":6,\"type\":\"SCALAR\"}]"},
        {.what = "index out of range", .err = TW_ERR_FORMAT,
         .want = "indices: accessors[1] element 2 is 2, not below the vertex count 2",
         .accessors = "[{\"bufferView\":0,\"componentType\":5126,\"count\":2,\"type\":\"VEC3\"},"
                      "{\"bufferView\":1,\"componentType\":5123,\"count\":6,\"type\":\"SCALAR\"}]"},
        {.what = "dangling material", .err = TW_ERR_FORMAT,
         .want = "material: 2 is not a material",
         .primitive = "{\"attributes\":{\"POSITION\":0},\"indices\":1,\"material\":2}"},
        {.what = "version", .err = TW_ERR_FORMAT,
         .want = "asset.version",
         .extra = "\"asset\":{\"version\":\"1.0\"}"},
        {.what = "required extension", .err = TW_ERR_FORMAT,
         .want = "extensionsRequired[0]: \"KHR_draco_mesh_compression\" is not supported",
         .extra = "\"extensionsUsed\":[\"KHR_draco_mesh_compression\"],"
                  "\"extensionsRequired\":[\"KHR_draco_mesh_compression\"]"},
        {.what = "nothing drawn", .err = TW_ERR_FORMAT, .want = "draws nothing", .nodes = "[{}]"},
    };
    for (size_t k = 0; k < sizeof(refused) / sizeof(refused[0]); k++)
        expect_refused(refused[k].what, refused[k].err, refused[k].want, refused[k].accessors,
                       refused[k].primitive, refused[k].nodes, refused[k].scenes,
                       refused[k].extra);
    /* tinygltf keeps only the matrix when a node has both. */
    err = import_doc(NULL, NULL,
                     "[{\"mesh\":0,\"matrix\":[1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1],"
                     "\"translation\":[100,0,0]}]",
                     NULL, NULL, NULL, &cap, &s);
    CHECK_MSG(err == 0 && near(s->bounds.max[0], 2.0f), "matrix and TRS: %s", cap.last);
    tw_gltf_scene_destroy(s);
    /* 45 nodes each scaling by 1e7, each under the last: every one is within
     * the node limit, their product is not finite. */
    char chain[2048] = "[";
    for (int k = 1; k <= 45; k++)
        snprintf(chain + strlen(chain), sizeof(chain) - strlen(chain),
                 "{\"scale\":[1e7,1e7,1e7],\"children\":[%d]},", k);
    strcat(chain, "{\"mesh\":0}]");
    expect_refused("composed transform overflow", TW_ERR_FORMAT, "is not finite", NULL, NULL,
                   chain, NULL, NULL);
    char deep[3000] = "\"extras\":";
    for (int k = 0; k < 1000; k++)
        strcat(deep, "[");
    for (int k = 0; k < 1000; k++)
        strcat(deep, "]");
    expect_refused("deep JSON", TW_ERR_FORMAT, "levels deep", NULL, NULL, NULL, NULL, deep);

    /* A position that is not finite. */
    const float bad_positions[15] = {0, 0, 0, 1, 0, 0, 0, NAN, 0, 1, 1, 0, 2, 0, 0};
    make_data(bad_positions);
    expect_refused("NaN position", TW_ERR_FORMAT, "element 2 is not finite", NULL, NULL, NULL,
                   NULL, NULL);
    make_data(NULL);

    /* Found by libFuzzer: a BIN chunk whose length ignores its 8-byte header
     * made tinygltf 2.7 read past the end of the input. */
    static const uint8_t overlong_bin[104] =
        "glTF\x02\0\0\0\x68\0\0\0\x3c\0\0\0JSON"
        "{\"asset\":{\"version\":\"4.0\"},\"buffers\":[{\"byteLength\":17}]}   "
        "\x18\0\0\0BIN\0\0\x01\x02\x03\x04\x05\x06\x07\x08\x09\x0a\x0b\x0c\x0d\x0e\x0f";
    {
        const struct tw_log clog = {capture, &cap};
        cap.errors = 0;
        err = tw_gltf_import_memory(overlong_bin, sizeof(overlong_bin), "overlong.glb", NULL, NULL,
                                    &clog, &s);
        CHECK_MSG(err == TW_ERR_FORMAT && strstr(cap.last, "overruns the file") && s == NULL,
                  "overlong BIN chunk: %s", cap.last);
    }

    /* Garbage and emptiness. */
    const struct tw_log log = {capture, &cap};
    cap.errors = 0;
    err = tw_gltf_import_memory("", 0, "empty.gltf", NULL, NULL, &log, &s);
    CHECK_MSG(err != 0 && cap.errors == 1 && s == NULL, "empty input");
    cap.errors = 0;
    err = tw_gltf_import_memory("glTF\2\0\0\0", 8, "short.glb", NULL, NULL, &log, &s);
    CHECK_MSG(err != 0 && cap.errors == 1 && s == NULL, "short glb");
    cap.errors = 0;
    err = tw_gltf_import("/nonexistent/x.glb", NULL, &log, &s);
    CHECK_MSG(err == TW_ERR_IO && cap.errors == 1 && strstr(cap.last, "/nonexistent/x.glb: no such file"),
              "missing file: %s", cap.last);
    tw_gltf_scene_destroy(NULL);
}

/* ---- running out of memory inside tinygltf --------------------------------- */

/* In a child process whose address space is capped, a document with a 48 MB
 * data URI makes tinygltf's allocations fail (std::bad_alloc): the import
 * must be refused with one message, not abort. ASan reserves terabytes of
 * shadow memory, so the cap cannot be applied under it. */
static void test_out_of_memory(void)
{
#ifdef UNDER_ASAN
    printf("out-of-memory test: not run under AddressSanitizer\n");
#else
    fflush(NULL);
    const pid_t pid = fork();
    if (pid == 0) {
        const size_t data_chars = 48u << 20;
        const char head[] = "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":37748736,"
                            "\"uri\":\"data:application/octet-stream;base64,";
        const char tail[] = "\"}]}";
        const size_t n = sizeof(head) - 1 + data_chars + sizeof(tail) - 1;
        char *doc = malloc(n);
        if (!doc)
            _exit(3);
        memcpy(doc, head, sizeof(head) - 1);
        memset(doc + sizeof(head) - 1, 'A', data_chars);
        memcpy(doc + sizeof(head) - 1 + data_chars, tail, sizeof(tail) - 1);
        unsigned long pages = 0;
        FILE *statm = fopen("/proc/self/statm", "r");
        if (!statm || fscanf(statm, "%lu", &pages) != 1)
            _exit(3);
        fclose(statm);
        const rlim_t cap = (rlim_t)pages * (rlim_t)sysconf(_SC_PAGESIZE) + (64u << 20);
        const struct rlimit rl = {cap, cap};
        if (setrlimit(RLIMIT_AS, &rl) != 0)
            _exit(3);
        struct captured_log cap_log = {"", 0};
        const struct tw_log log = {capture, &cap_log};
        struct tw_gltf_scene *s = NULL;
        const int err = tw_gltf_import_memory(doc, n, "big.gltf", NULL, NULL, &log, &s);
        fprintf(stderr, "out-of-memory test: error %d: %s\n", err, cap_log.last);
        _exit(err != 0 && s == NULL && cap_log.errors == 1 ? 0 : 1);
    }
    int status = 0;
    CHECK_MSG(pid > 0 && waitpid(pid, &status, 0) == pid, "fork");
    CHECK_MSG(WIFEXITED(status) && WEXITSTATUS(status) == 0,
              "out of memory inside tinygltf: the child %s %d",
              WIFEXITED(status) ? "exited with" : "died of signal",
              WIFEXITED(status) ? WEXITSTATUS(status) : WTERMSIG(status));
#endif
}

/* ---- external buffers and manifests in a temporary folder ----------------------- */

static char tmp_root[64];

static void write_text(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    CHECK_MSG(f != NULL, "cannot write %s", path);
    if (f) {
        fputs(text, f);
        fclose(f);
    }
}

static void copy_file(const char *from, const char *to)
{
    FILE *in = fopen(from, "rb"), *out = fopen(to, "wb");
    CHECK_MSG(in && out, "cannot copy %s to %s", from, to);
    if (in && out) {
        char buf[65536];
        size_t n;
        while ((n = fread(buf, 1, sizeof(buf), in)) > 0)
            fwrite(buf, 1, n, out);
    }
    if (in)
        fclose(in);
    if (out)
        fclose(out);
}

static void copy_asset(const char *relative, const char *to_dir, const char *to_name)
{
    char *from = join(shared_dir, relative);
    char *to = join(to_dir, to_name);
    copy_file(from, to);
    free(from);
    free(to);
}

static void remove_tree(const char *dir)
{
    struct dirent **entries = NULL;
    const int n = scandir(dir, &entries, NULL, alphasort);
    for (int k = 0; k < n; k++) {
        const char *name = entries[k]->d_name;
        if (strcmp(name, ".") != 0 && strcmp(name, "..") != 0) {
            char *path = join(dir, name);
            struct stat st;
            if (lstat(path, &st) == 0 && S_ISDIR(st.st_mode))
                remove_tree(path);
            else
                unlink(path);
            free(path);
        }
        free(entries[k]);
    }
    free(entries);
    rmdir(dir);
}

static void test_external_buffers(const char *dir)
{
    /* m/ holds a .gltf whose buffer lies elsewhere. */
    char *bin = join(dir, "m/tri.bin");
    const float tri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    FILE *f = fopen(bin, "wb");
    if (f) {
        fwrite(tri, sizeof(tri), 1, f);
        fclose(f);
    }
    char *outside = join(dir, "outside.bin");
    copy_file(bin, outside);
    const struct {
        const char *uri;
        int err;
        const char *want;
    } cases[] = {
        {"tri.bin", 0, NULL},
        {"./sub/../tri.bin", TW_ERR_IO, "does not exist"},
        {"../outside.bin", TW_ERR_FORMAT, "climbs out"},
        {"/etc/hostname", TW_ERR_FORMAT, "absolute path"},
        {"file:///etc/hostname", TW_ERR_FORMAT, "is a URI"},
        {"http://example.com/tri.bin", TW_ERR_FORMAT, "is a URI"},
        {"missing.bin", TW_ERR_IO, "does not exist"},
    };
    char *gltf = join(dir, "m/ext.gltf");
    for (size_t k = 0; k < sizeof(cases) / sizeof(cases[0]); k++) {
        char doc[1024];
        snprintf(doc, sizeof(doc),
                 "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":36,\"uri\":\"%s\"}],"
                 "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
                 "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":3,"
                 "\"type\":\"VEC3\"}],"
                 "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                 "\"nodes\":[{\"mesh\":0}],\"scenes\":[{\"nodes\":[0]}]}",
                 cases[k].uri);
        write_text(gltf, doc);
        struct captured_log cap = {"", 0};
        const struct tw_log log = {capture, &cap};
        struct tw_gltf_scene *s = NULL;
        const int err = tw_gltf_import(gltf, NULL, &log, &s);
        CHECK_MSG(err == cases[k].err && (!cases[k].want || strstr(cap.last, cases[k].want)),
                  "buffer uri %s: error %d, \"%s\"", cases[k].uri, err, cap.last);
        if (!err)
            CHECK_MSG(s->triangle_count == 1, "external buffer triangle");
        tw_gltf_scene_destroy(s);
    }
    unlink(gltf);
    free(gltf);
    free(outside);
    free(bin);
}

/* Writes the manifest text to dir/m/test.json and loads it. */
static int load_manifest_text(const char *dir, const char *text, struct captured_log *cap,
                              struct tw_tileset **ts)
{
    char *path = join(dir, "m/test.json");
    write_text(path, text);
    const struct tw_log log = {capture, cap};
    cap->errors = 0;
    cap->last[0] = '\0';
    const int err = tw_tilesets_load_manifest(path, NULL, &log, ts);
    free(path);
    return err;
}

static void expect_manifest_refused(const char *dir, const char *what, const char *text,
                                    const char *want)
{
    struct captured_log cap;
    struct tw_tileset *ts = NULL;
    const int err = load_manifest_text(dir, text, &cap, &ts);
    char *path = join(dir, "m/test.json");
    CHECK_MSG(err != 0 && ts == NULL && cap.errors == 1 && strstr(cap.last, want) &&
                  starts_with(cap.last, path) && !strchr(cap.last, '\n'),
              "%s: error %d, \"%s\" (expected \"%s\")", what, err, cap.last, want);
    free(path);
    tw_tileset_destroy(ts);
}

static void test_manifests(void)
{
    snprintf(tmp_root, sizeof(tmp_root), "/tmp/tw-test-gltf-XXXXXX");
    if (!mkdtemp(tmp_root)) {
        CHECK_MSG(false, "cannot create a temporary folder");
        return;
    }
    char *m = join(tmp_root, "m");
    mkdir(m, 0755);
    copy_asset("assets/models/city/kenney-city-builder/road-straight.glb", m, "road.glb");
    copy_asset("assets/models/city/kenney-city-builder/building-small-a.glb", m, "house.glb");
    copy_asset("assets/models/city/kenney-city-builder/road-straight.glb", tmp_root,
               "outside.glb");
    copy_asset("assets/bad/gltf-validator/mesh_data/index_buffer_oob.gltf", m, "oob.gltf");
    copy_asset("assets/bad/gltf-validator/mesh_data/index_buffer_oob.bin", m,
               "index_buffer_oob.bin");
    char *link = join(m, "link.glb");
    CHECK_MSG(symlink("../outside.glb", link) == 0, "cannot make a symbolic link");

    test_external_buffers(tmp_root);

    /* A FIFO is refused, not waited on. */
    char *fifo = join(m, "fifo.glb");
    CHECK_MSG(mkfifo(fifo, 0600) == 0, "cannot make a FIFO");
    {
        struct captured_log fcap = {"", 0};
        const struct tw_log flog = {capture, &fcap};
        struct tw_gltf_scene *fs = NULL;
        const int ferr = tw_gltf_import(fifo, NULL, &flog, &fs);
        CHECK_MSG(ferr == TW_ERR_IO && strstr(fcap.last, "is not a regular file"), "FIFO: %s",
                  fcap.last);
        tw_gltf_scene_destroy(fs);
    }
    free(fifo);

    /* A good manifest, both forms; road.glb is placed three times, the third
     * time by the path third_road. */
    static const char good_manifest[] =
        "{\"name\": \"test-city\", \"footprint\": [30, 20],\n"
        " \"comment\": \"a test\", \"max_cluster_triangles\": 64,\n"
        " \"prototypes\": [\n"
        "  {\"name\": \"one\", \"gltf\": \"house.glb\", \"scale\": 10,\n"
        "   \"offset\": [5, 0, 5], \"weight\": 2},\n"
        "  {\"name\": \"block\", \"objects\": [\n"
        "    {\"gltf\": \"road.glb\", \"position\": [5, 0, 5], \"scale\": 10},\n"
        "    {\"gltf\": \"./road.glb\", \"position\": [15, 0, 5], \"scale\": 10,\n"
        "     \"yaw\": 90},\n"
        "    {\"gltf\": \"%s\", \"position\": [25, 0, 5]},\n"
        "    {\"gltf\": \"house.glb\", \"position\": [5, 0, 15], \"yaw\": 180}\n"
        "  ]}\n"
        " ]}\n";
    char manifest[1024];
    struct captured_log cap;
    struct tw_tileset *ts = NULL;
    /* A path through a folder that does not exist is refused, though it
     * would lead back to road.glb. */
    snprintf(manifest, sizeof(manifest), good_manifest, "sub/../road.glb");
    int err = load_manifest_text(tmp_root, manifest, &cap, &ts);
    CHECK_MSG(err == TW_ERR_IO && strstr(cap.last, "sub/../road.glb"),
              "a missing folder in a path: %d %s", err, cap.last);
    snprintf(manifest, sizeof(manifest), good_manifest, "road.glb");
    err = load_manifest_text(tmp_root, manifest, &cap, &ts);
    CHECK_MSG(err == 0 && ts, "good manifest: %s", cap.last);
    if (ts) {
        CHECK_MSG(strcmp(ts->name, "test-city") == 0, "name %s", ts->name);
        CHECK_MSG(ts->footprint[0] == 30.0f && ts->footprint[1] == 20.0f, "footprint");
        CHECK_MSG(ts->prototype_count == 2, "%u prototypes", ts->prototype_count);
        CHECK_MSG(ts->finished && ts->max_cluster_triangles == 64, "finished with 64");
        CHECK_MSG(strcmp(ts->prototypes[0].name, "one") == 0 && ts->prototypes[0].weight == 2.0f,
                  "prototype 0");
        /* The files' 452 and 54 triangles less those without area (12 and
         * 1, collinear corners), which finishing drops. */
        CHECK_MSG(ts->prototypes[0].triangle_count == 440, "one: %llu triangles",
                  (unsigned long long)ts->prototypes[0].triangle_count);
        CHECK_MSG(ts->prototypes[1].triangle_count == 3 * 53 + 440, "block: %llu triangles",
                  (unsigned long long)ts->prototypes[1].triangle_count);
        /* house.glb imported once, road.glb once: meshes shared. */
        uint32_t meshes_used = 0;
        for (uint32_t k = 0; k < ts->mesh_count; k++) {
            bool used = false;
            for (uint32_t p = 0; p < ts->prototype_count && !used; p++)
                for (uint32_t i = 0; i < ts->prototypes[p].instance_count && !used; i++)
                    used = ts->prototypes[p].instances[i].mesh == k;
            meshes_used += used;
        }
        CHECK_MSG(meshes_used == ts->mesh_count, "every mesh used");
        CHECK_MSG(ts->prototypes[1].instance_count > ts->mesh_count - ts->prototypes[0].instance_count,
                  "road meshes shared: %u instances, %u meshes", ts->prototypes[1].instance_count,
                  ts->mesh_count);
        /* The scaled house (1 x 0.95 x 1 units) at offset (5, 0, 5). */
        const struct tw_box *b = &ts->prototypes[0].box;
        CHECK_MSG(near(b->min[0], 0) && near(b->max[0], 10) && near(b->min[2], 0) &&
                      near(b->max[2], 10) && near(b->min[1], 0) && fabsf(b->max[1] - 9.5f) < 0.1f,
                  "house box [%g %g %g]..[%g %g %g]", b->min[0], b->min[1], b->min[2], b->max[0],
                  b->max[1], b->max[2]);
    }
    tw_tileset_destroy(ts);

    /* Refusals: each names the manifest, the place and the reason. */
    const char *d = tmp_root;
#define PROTO(body) "{\"footprint\": [10, 10], \"prototypes\": [" body "]}"
    static const struct {
        const char *what, *text, *want;
    } refusals[] = {
        {"escape",
         PROTO("{\"name\": \"a\", \"gltf\": \"../outside.glb\"}"),
         "prototypes[0].gltf: \"../outside.glb\" climbs out"},
        {"deep escape",
         PROTO("{\"name\": \"a\", \"objects\": [{\"gltf\": \"road.glb\"}, "
               "{\"gltf\": \"x/../../outside.glb\"}]}"),
         "prototypes[0].objects[1].gltf: \"x/../../outside.glb\" climbs out"},
        {"http",
         PROTO("{\"name\": \"a\", \"gltf\": \"http://example.com/a.glb\"}"),
         "prototypes[0].gltf: \"http://example.com/a.glb\" is a URI"},
        {"file URI", PROTO("{\"name\": \"a\", \"gltf\": \"file:road.glb\"}"), "is a URI"},
        {"backslash", PROTO("{\"name\": \"a\", \"gltf\": \"..\\\\outside.glb\"}"), "backslash"},
        {"symbolic link", PROTO("{\"name\": \"a\", \"gltf\": \"link.glb\"}"), "symbolic link"},
        {"missing file",
         PROTO("{\"name\": \"a\", \"gltf\": \"nope.glb\"}"),
         "prototypes[0].gltf: \"nope.glb\" does not exist"},
        {"FIFO",
         PROTO("{\"name\": \"a\", \"gltf\": \"fifo.glb\"}"),
         "\"fifo.glb\" is not a regular file"},
        {"folder",
         PROTO("{\"name\": \"a\", \"gltf\": \".\"}"),
         "\".\" is the document's folder, not a file"},
        {"unknown key",
         PROTO("{\"name\": \"a\", \"gltf\": \"road.glb\", \"scael\": 2}"),
         "prototypes[0]: unknown key \"scael\""},
        {"unknown object key",
         PROTO("{\"name\": \"a\", \"objects\": [{\"gltf\": \"road.glb\", "
               "\"offset\": [1, 2, 3]}]}"),
         "prototypes[0].objects[0]: unknown key \"offset\""},
        {"unknown top key",
         "{\"footprint\": [10, 10], \"prototype\": []}",
         "(top level): unknown key \"prototype\""},
        {"footprint type",
         "{\"footprint\": \"10\", \"prototypes\": []}",
         "footprint: must be an array of 2 numbers, not a string"},
        {"footprint sign",
         "{\"footprint\": [10, -1], \"prototypes\": []}",
         "footprint: both sides must be positive"},
        {"missing footprint", "{\"prototypes\": []}", "footprint: is missing"},
        {"no prototypes",
         "{\"footprint\": [10, 10], \"prototypes\": []}",
         "prototypes: has 0 prototypes"},
        {"weight type",
         PROTO("{\"name\": \"a\", \"gltf\": \"road.glb\", \"weight\": \"1\"}"),
         "prototypes[0].weight: must be a number, not a string"},
        {"weight zero",
         PROTO("{\"name\": \"a\", \"gltf\": \"road.glb\", \"weight\": 0}"),
         "prototypes[0].weight: 0 is not in [1e-06, 1e+06]"},
        {"scale negative",
         PROTO("{\"name\": \"a\", \"objects\": [{\"gltf\": \"road.glb\", "
               "\"scale\": -1}]}"),
         "prototypes[0].objects[0].scale: -1 is not in [1e-06, 1e+06]"},
        {"position length",
         PROTO("{\"name\": \"a\", \"objects\": [{\"gltf\": \"road.glb\", "
               "\"position\": [1, 2]}]}"),
         "prototypes[0].objects[0].position: must be an array of 3 numbers"},
        {"position element",
         PROTO("{\"name\": \"a\", \"objects\": [{\"gltf\": \"road.glb\", "
               "\"position\": [1, true, 2]}]}"),
         "prototypes[0].objects[0].position: must be a number, not a boolean"},
        {"objects type",
         PROTO("{\"name\": \"a\", \"objects\": {}}"),
         "prototypes[0].objects: must be an array, not an object"},
        {"object type",
         PROTO("{\"name\": \"a\", \"objects\": [3]}"),
         "prototypes[0].objects[0]: must be an object, not a number"},
        {"gltf type",
         PROTO("{\"name\": \"a\", \"gltf\": 3}"),
         "prototypes[0].gltf: must be a string, not a number"},
        {"name type",
         PROTO("{\"name\": 5, \"gltf\": \"road.glb\"}"),
         "prototypes[0].name: must be a string"},
        {"name missing", PROTO("{\"gltf\": \"road.glb\"}"), "prototypes[0].name: is missing"},
        {"duplicate names",
         PROTO("{\"name\": \"a\", \"gltf\": \"road.glb\"},"
               "{\"name\": \"a\", \"gltf\": \"road.glb\"}"),
         "prototypes[1].name: \"a\" is already the name of prototypes[0]"},
        {"both forms",
         PROTO("{\"name\": \"a\", \"gltf\": \"road.glb\", \"objects\": []}"),
         "must have either \"gltf\" or \"objects\", not both"},
        {"neither form", PROTO("{\"name\": \"a\"}"), "must have either \"gltf\" or \"objects\""},
        {"cluster type",
         "{\"footprint\": [10, 10], \"max_cluster_triangles\": 1.5, "
         "\"prototypes\": [{\"name\": \"a\", \"gltf\": \"road.glb\"}]}",
         "max_cluster_triangles: must be an integer"},
        {"bad glTF inside",
         PROTO("{\"name\": \"a\", \"gltf\": \"oob.gltf\"}"),
         "prototypes[0].gltf: "},
        {"not an object", "[1, 2]", "must be a JSON object, not an array"},
        {"syntax", "{\"footprint\": [10, 10],,}", "line 1, column"},
        {"NaN",
         PROTO("{\"name\": \"a\", \"gltf\": \"road.glb\", "
               "\"scale\": NaN}"),
         "prototypes[0].scale: must be a finite number"},
        {"trailing text", "{\"footprint\": [10, 10]} x", "line 1, column 25"},
        {"unclosed", "{\"footprint\": [10, 10]", "ends early"},
        {"empty", "", "ends early"},
    };
    for (size_t k = 0; k < sizeof(refusals) / sizeof(refusals[0]); k++)
        expect_manifest_refused(d, refusals[k].what, refusals[k].text, refusals[k].want);
    char text[1024];
    snprintf(text, sizeof(text), PROTO("{\"name\": \"a\", \"gltf\": \"%s/outside.glb\"}"), d);
    expect_manifest_refused(d, "absolute", text, "is an absolute path");
#undef PROTO
    /* The glTF message is carried whole, after the manifest's place. */
    err = load_manifest_text(tmp_root,
                             "{\"footprint\": [10, 10], \"prototypes\": "
                             "[{\"name\": \"a\", \"gltf\": \"oob.gltf\"}]}",
                             &cap, &ts);
    CHECK_MSG(err == TW_ERR_FORMAT && strstr(cap.last, "oob.gltf: meshes[0].primitives[0].indices"),
              "glTF error inside a manifest: %s", cap.last);

    struct captured_log cap2 = {"", 0};
    const struct tw_log log = {capture, &cap2};
    err = tw_tilesets_load_manifest("/nonexistent/x.json", NULL, &log, &ts);
    CHECK_MSG(err == TW_ERR_IO && cap2.errors == 1 && ts == NULL, "missing manifest");
    err = tw_tilesets_load_manifest(tmp_root, NULL, &log, &ts);
    CHECK_MSG(err != 0 && ts == NULL, "a folder as a manifest");

    free(link);
    free(m);
    remove_tree(tmp_root);
}

/* ---- binding and placing ------------------------------------------------------------ */

static void test_bind_place(void)
{
    struct captured_log cap;
    struct tw_gltf_scene *s = NULL;
    int err = import_one("assets/models/city/kenney-city-builder/road-straight-lightposts.glb",
                         &cap, &s);
    CHECK_MSG(err == 0, "lightposts: %s", cap.last);
    if (err)
        return;
    struct tw_tileset *ts = NULL;
    CHECK_MSG(tw_tileset_create("t", 10, 10, &ts) == 0, "create");
    CHECK_MSG(tw_tileset_add_prototype(ts, "p", 1) == 0, "prototype");
    struct tw_gltf_binding b;
    CHECK_MSG(tw_gltf_bind(s, ts, &b) == 0, "bind");
    CHECK_MSG(ts->mesh_count == s->primitive_count, "%u meshes for %u primitives", ts->mesh_count,
              s->primitive_count);
    float placement[12];
    const float position[3] = {5, 0, 5};
    tw_gltf_placement(position, 90.0f, 10.0f, placement);
    CHECK_MSG(near(placement[2], 10.0f) && near(placement[8], -10.0f) && near(placement[3], 5.0f),
              "yaw 90 turns +z towards +x");
    CHECK_MSG(tw_gltf_place(s, &b, ts, 0, placement) == 0, "place");
    CHECK_MSG(tw_gltf_place(s, &b, ts, 0, NULL) == 0, "place again");
    CHECK_MSG(ts->mesh_count == s->primitive_count, "placing adds no mesh");
    CHECK_MSG(tw_gltf_place(s, &b, ts, 1, NULL) == TW_ERR_INVALID, "no such prototype");
    CHECK_MSG(tw_tileset_finish(ts, 0) == 0, "finish");
    /* Placed twice, less the file's 7 triangles without area (collinear
     * corners), which finishing drops. */
    CHECK_MSG(ts->prototypes[0].triangle_count == 2 * (s->triangle_count - 7), "%llu triangles",
              (unsigned long long)ts->prototypes[0].triangle_count);
    tw_tileset_destroy(ts);
    tw_gltf_scene_destroy(s);
}

/* ---- base colours baked from textures ------------------------------------------- */

struct warning_log {
    char last[2048];
    int warnings, errors;
};

static void capture_warnings(void *user, enum tw_log_level level, const char *msg)
{
    struct warning_log *w = user;
    if (level == TW_LOG_WARN) {
        w->warnings++;
        snprintf(w->last, sizeof(w->last), "%s", msg);
    } else if (level == TW_LOG_ERROR) {
        w->errors++;
    }
}

static uint64_t primitive_triangles_total(const struct tw_gltf_scene *s)
{
    uint64_t n = 0;
    for (uint32_t k = 0; k < s->primitive_count; k++)
        n += s->primitives[k].triangle_count;
    return n;
}

/* Imports path with a warning log. */
static int import_warned(const char *path, struct warning_log *w, struct tw_gltf_scene **s)
{
    memset(w, 0, sizeof(*w));
    const struct tw_log log = {capture_warnings, w};
    return tw_gltf_import(path, NULL, &log, s);
}

static void test_baked_colours(void)
{
    static const char *const pieces[] = {"building-small-a.glb", "building-garage.glb",
                                         "road-straight.glb", "grass-trees.glb"};
    char dir[64] = "/tmp/test-gltf-colours-XXXXXX";
    CHECK_MSG(mkdtemp(dir) != NULL, "mkdtemp");
    for (size_t p = 0; p < sizeof(pieces) / sizeof(pieces[0]); p++) {
        char relative[128];
        snprintf(relative, sizeof(relative), "tilesets/kenney-city/%s", pieces[p]);
        char *path = join(source_root, relative);
        struct warning_log w;
        struct tw_gltf_scene *s = NULL;
        int err = import_warned(path, &w, &s);
        CHECK_MSG(err == 0 && w.warnings == 0, "%s: error %d, %d warnings (%s)", pieces[p], err,
                  w.warnings, w.last);
        free(path);
        if (err)
            continue;
        /* Materials that primitives use: several, distinct, not all white. */
        uint32_t used = 0, coloured = 0;
        bool distinct = true;
        for (uint32_t m = 0; m < s->material_count; m++) {
            bool is_used = false;
            for (uint32_t k = 0; k < s->primitive_count; k++)
                is_used |= s->primitives[k].material == m;
            if (!is_used)
                continue;
            used++;
            const float *c = s->materials[m].base_color;
            coloured += c[0] < 0.9f || c[1] < 0.9f || c[2] < 0.9f;
            for (uint32_t n = 0; n < m; n++)
                if (memcmp(s->materials[n].base_color, c, sizeof(float) * 3) == 0)
                    distinct = false;
        }
        CHECK_MSG(used > 1 && coloured > 1 && distinct && used <= 65,
                  "%s: %u materials used, %u coloured, distinct %d", pieces[p], used, coloured,
                  distinct);
        CHECK_MSG(s->mesh_count == 1 && s->meshes[0].primitive_count == s->primitive_count,
                  "%s: one mesh holds every part", pieces[p]);
        CHECK_MSG(primitive_triangles_total(s) == s->unique_triangles,
                  "%s: %llu triangles in the parts, %llu in the file", pieces[p],
                  (unsigned long long)primitive_triangles_total(s),
                  (unsigned long long)s->unique_triangles);
        for (uint32_t k = 0; k < s->primitive_count; k++) {
            const struct tw_gltf_primitive *q = &s->primitives[k];
            bool in_range = q->triangle_count > 0 && q->vertex_count > 0;
            for (uint64_t i = 0; i < 3ull * q->triangle_count; i++)
                in_range &= q->indices[i] < q->vertex_count;
            CHECK_MSG(in_range, "%s: primitive %u has indices out of range", pieces[p], k);
        }
        printf("  %-24s %u primitives, %u materials used\n", pieces[p], s->primitive_count,
               used);

        /* The same piece without its texture: a warning, the base colour, the
         * same triangles. Then with a file that is not a PNG. */
        char *copy = join(dir, pieces[p]);
        char *from = join(source_root, relative);
        copy_file(from, copy);
        free(from);
        struct tw_gltf_scene *plain = NULL;
        err = import_warned(copy, &w, &plain);
        CHECK_MSG(err == 0 && w.warnings == 1 && w.errors == 0 &&
                      strstr(w.last, "Textures/colormap.png") && strstr(w.last, pieces[p]),
                  "%s without its texture: error %d, %d warnings: %s", pieces[p], err, w.warnings,
                  w.last);
        if (!err) {
            CHECK_MSG(plain->primitive_count == 1 && plain->material_count == 1 &&
                          near(plain->materials[0].base_color[0], 1.0f) &&
                          near(plain->materials[0].base_color[2], 1.0f),
                      "%s without its texture: %u primitives, %u materials", pieces[p],
                      plain->primitive_count, plain->material_count);
            CHECK_MSG(plain->triangle_count == s->triangle_count &&
                          primitive_triangles_total(plain) == primitive_triangles_total(s),
                      "%s: the split changed the triangle total", pieces[p]);
        }
        tw_gltf_scene_destroy(plain);
        free(copy);
        tw_gltf_scene_destroy(s);
    }

    char *textures = join(dir, "Textures");
    mkdir(textures, 0700);
    char *fake = join(textures, "colormap.png");
    write_text(fake, "not a PNG at all");
    char *copy = join(dir, pieces[0]);
    struct warning_log w;
    struct tw_gltf_scene *s = NULL;
    int err = import_warned(copy, &w, &s);
    CHECK_MSG(err == 0 && w.warnings == 1 && strstr(w.last, "not a PNG") && s &&
                  s->primitive_count == 1,
              "not a PNG: error %d, %d warnings: %s", err, w.warnings, w.last);
    tw_gltf_scene_destroy(s);
    /* A PNG cut short. */
    char *real = join(source_root, "tilesets/kenney-city/Textures/colormap.png");
    FILE *in = fopen(real, "rb"), *out = fopen(fake, "wb");
    if (in && out) {
        char buf[600];
        const size_t n = fread(buf, 1, sizeof(buf), in);
        fwrite(buf, 1, n, out);
    }
    if (in)
        fclose(in);
    if (out)
        fclose(out);
    s = NULL;
    err = import_warned(copy, &w, &s);
    CHECK_MSG(err == 0 && w.warnings == 1 && strstr(w.last, "cannot decode") && s &&
                  s->primitive_count == 1,
              "truncated PNG: error %d, %d warnings: %s", err, w.warnings, w.last);
    tw_gltf_scene_destroy(s);
    /* A texture outside the folder is refused like a buffer would be. */
    unlink(fake);
    CHECK_MSG(symlink(real, fake) == 0, "symlink");
    s = NULL;
    err = import_warned(copy, &w, &s);
    CHECK_MSG(err == 0 && w.warnings == 1 && s && s->primitive_count == 1,
              "texture outside the folder: error %d, %d warnings: %s", err, w.warnings, w.last);
    tw_gltf_scene_destroy(s);
    free(real);
    free(copy);
    free(fake);
    free(textures);
    remove_tree(dir);

    /* The forest's tree embeds its leaves (a bufferView PNG). */
    char *tree = join(source_root, "tilesets/cesium-forest/tree_CC0.glb");
    s = NULL;
    err = import_warned(tree, &w, &s);
    CHECK_MSG(err == 0 && w.warnings == 0 && s && s->primitive_count > 2 &&
                  primitive_triangles_total(s) == 2076,
              "tree: error %d, %d warnings (%s)", err, w.warnings, w.last);
    tw_gltf_scene_destroy(s);
    free(tree);
}

/* ---- the shipped manifests -------------------------------------------------------- */

/* The triangles of ts's clusters whose corners are exactly collinear (or
 * coincident): none should be left to draw. Modelled T-junction fillers are
 * such triangles, and on kenney-city one of them once gave the near plane's
 * depth to a pixel of a cluster 67 m away. */
static uint64_t collinear_triangles(const struct tw_tileset *ts)
{
    uint64_t found = 0;
    for (uint32_t p = 0; p < ts->prototype_count; p++) {
        const struct tw_prototype *proto = &ts->prototypes[p];
        for (uint32_t c = 0; c < proto->cluster_count; c++) {
            const struct tw_mesh_part *part = &ts->parts[proto->clusters[c].part];
            const struct tw_mesh *m = &ts->meshes[part->mesh];
            for (uint32_t t = part->first_triangle;
                 t < part->first_triangle + part->triangle_count; t++) {
                const float *v[3];
                for (int k = 0; k < 3; k++)
                    v[k] = m->positions + 3 * (size_t)m->indices[3 * (size_t)t + k];
                double e1[3], e2[3];
                for (int k = 0; k < 3; k++) {
                    e1[k] = (double)v[1][k] - v[0][k];
                    e2[k] = (double)v[2][k] - v[0][k];
                }
                found += e1[1] * e2[2] - e1[2] * e2[1] == 0.0 &&
                         e1[2] * e2[0] - e1[0] * e2[2] == 0.0 &&
                         e1[0] * e2[1] - e1[1] * e2[0] == 0.0;
            }
        }
    }
    return found;
}

static void test_shipped(const char *relative, uint32_t min_prototypes)
{
    char *path = join(source_root, relative);
    struct captured_log cap = {"", 0};
    const struct tw_log log = {capture, &cap};
    struct tw_tileset *ts = NULL;
    const int err = tw_tilesets_load_manifest(path, NULL, &log, &ts);
    CHECK_MSG(err == 0, "%s: %s", relative, cap.last);
    if (!err) {
        CHECK_MSG(ts->prototype_count >= min_prototypes, "%s: %u prototypes", relative,
                  ts->prototype_count);
        printf("%s: \"%s\", footprint %g x %g, %u meshes\n", relative, ts->name, ts->footprint[0],
               ts->footprint[1], ts->mesh_count);
        for (uint32_t k = 0; k < ts->prototype_count; k++) {
            const struct tw_prototype *p = &ts->prototypes[k];
            printf("  %-20s weight %4.1f  %7llu triangles  %4u instances  %4u clusters  "
                   "height %.1f m\n",
                   p->name, p->weight, (unsigned long long)p->triangle_count, p->instance_count,
                   p->cluster_count, p->box.max[1]);
            CHECK_MSG(p->box.min[0] > -0.5f && p->box.min[2] > -0.5f &&
                          p->box.max[0] < ts->footprint[0] + 0.5f &&
                          p->box.max[2] < ts->footprint[1] + 0.5f,
                      "%s: %s spills out of its tile", relative, p->name);
        }
        const uint64_t collinear = collinear_triangles(ts);
        CHECK_MSG(collinear == 0, "%s: %llu triangles with collinear corners are drawn", relative,
                  (unsigned long long)collinear);
    }
    tw_tileset_destroy(ts);
    free(path);
}

int main(int argc, char **argv)
{
    if (argc != 3) {
        fprintf(stderr, "usage: test-gltf SHARED_DIR SOURCE_ROOT\n");
        return 1;
    }
    shared_dir = argv[1];
    source_root = argv[2];
    struct stat st;
    if (stat(shared_dir, &st) != 0 || !S_ISDIR(st.st_mode)) {
        fprintf(stderr, "test-gltf: the shared folder %s is missing (it holds the test assets): "
                        "skipped\n",
                shared_dir);
        return 77;
    }
    test_bad_files();
    test_valid_models();
    test_synthetic();
    test_out_of_memory();
    test_bind_place();
    test_baked_colours();
    test_manifests();
    test_shipped("tilesets/kenney-city/kenney-city.json", 6);
    test_shipped("tilesets/cesium-forest/cesium-forest.json", 3);
    test_shipped("tilesets/cesium-buildings/cesium-buildings.json", 4);
    return check_summary("test-gltf");
}
