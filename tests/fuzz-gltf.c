/* Fuzz target for the glTF importer: LLVMFuzzerTestOneInput imports the
 * input from memory (no file access) and, when it imports, adds it to a
 * tileset and finishes it. Built with libFuzzer when TW_LIBFUZZER is defined
 * (clang, -fsanitize=fuzzer); otherwise a plain main runs the inputs named
 * on the command line (files, or folders walked recursively), each from
 * memory and also by path (so that external buffers are exercised), and
 * counts how many import. The seed corpus is ../shared/assets/bad. */
#include "tileworld/tilesets.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tilesets/gltf-scan.h"
#include "tilesets/gltf-shim.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static void exercise(const struct tw_gltf_scene *scene)
{
    struct tw_tileset *ts = NULL;
    struct tw_gltf_binding b;
    static const float placement[12] = {2, 0, 0, 10, 0, 2, 0, 0, 0, 0, 2, 10};
    if (tw_tileset_create("fuzz", 20.0f, 20.0f, &ts) == 0 &&
        tw_tileset_add_prototype(ts, "p", 1.0f) == 0 && tw_gltf_bind(scene, ts, &b) == 0 &&
        tw_gltf_place(scene, &b, ts, 0, placement) == 0 &&
        tw_gltf_place(scene, &b, ts, 0, NULL) == 0)
        tw_tileset_finish(ts, 64);
    tw_tileset_destroy(ts);
}

/* The importer's first pass (gltf-scan.h) must count what tinygltf makes of
 * the same JSON: its memory budget and tinygltf's reserved arrays rest on
 * it. */
static void check_scan(const uint8_t *data, size_t size)
{
    const uint8_t *text = data;
    size_t text_len = size;
    if (size >= 20 && memcmp(data, "glTF", 4) == 0) {
        const uint32_t n = (uint32_t)data[12] | (uint32_t)data[13] << 8 |
                           (uint32_t)data[14] << 16 | (uint32_t)data[15] << 24;
        if (n > size - 20)
            return;
        text = data + 20;
        text_len = n;
    }
    struct tw_gltf_scan scan;
    if (tw_gltf_scan(text, text_len, 256, &scan) || !scan.valid || scan.depth > 256 ||
        scan.values > (4u << 20) || scan.string_bytes > (8u << 20)) {
        tw_gltf_scan_finish(&scan);
        return;
    }
    struct tw_gltf_doc doc;
    char msg[256];
    if (tw_gltf_shim_load(data, size, NULL, scan.counts, &doc, msg, sizeof(msg)) == 0) {
        const uint64_t got[][2] = {
            {scan.counts[TW_GLTF_NODES], doc.node_count},
            {scan.counts[TW_GLTF_MESHES], doc.mesh_count},
            {scan.counts[TW_GLTF_ACCESSORS], doc.accessor_count},
            {scan.counts[TW_GLTF_BUFFER_VIEWS], doc.buffer_view_count},
            {scan.counts[TW_GLTF_BUFFERS], doc.buffer_count},
            {scan.counts[TW_GLTF_MATERIALS], doc.material_count},
            {scan.counts[TW_GLTF_SCENES], doc.scene_count},
            {scan.counts[TW_GLTF_TEXTURES], doc.texture_count},
            {scan.counts[TW_GLTF_IMAGES], doc.image_count},
            {scan.counts[TW_GLTF_SAMPLERS], doc.sampler_count},
            {scan.extensions_required_count, doc.extensions_required_count},
        };
        /* ... and read asset.version and minVersion as tinygltf does (the
         * version is checked on the scan, before tinygltf runs). */
        if ((scan.version.text && strlen(scan.version.text) == scan.version.length &&
             strcmp(scan.version.text, doc.version) != 0) ||
            (scan.min_version.text && strlen(scan.min_version.text) == scan.min_version.length &&
             strcmp(scan.min_version.text, doc.min_version) != 0)) {
            fprintf(stderr, "fuzz-gltf: the scan read asset.version \"%s\", minVersion \"%s\"; "
                            "tinygltf \"%s\", \"%s\"\n",
                    scan.version.text ? scan.version.text : "",
                    scan.min_version.text ? scan.min_version.text : "", doc.version,
                    doc.min_version);
            abort();
        }
        for (size_t k = 0; k < sizeof(got) / sizeof(got[0]); k++) {
            if (got[k][0] != got[k][1]) {
                fprintf(stderr, "fuzz-gltf: the scan counted %llu of kind %zu, tinygltf %llu\n",
                        (unsigned long long)got[k][0], k, (unsigned long long)got[k][1]);
                abort();
            }
        }
        tw_gltf_shim_free(&doc);
    }
    tw_gltf_scan_finish(&scan);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const struct tw_gltf_settings limits = {16u << 20, 1u << 20};
    struct tw_gltf_scene *scene = NULL;
    if (tw_gltf_import_memory(data, size, "fuzz-input", NULL, &limits, NULL, &scene) == 0)
        exercise(scene);
    tw_gltf_scene_destroy(scene);
    check_scan(data, size);
    return 0;
}

#ifndef TW_LIBFUZZER
#include "tests/fuzz-driver.h"
#include "tiles/tiles-internal.h"

struct counts {
    unsigned imported_memory, imported_path;
};

/* An input from memory, named after its file, then by path (so that its
 * external buffers are read), counting what imports. */
static void run_input(void *user, const char *path, const uint8_t *data, size_t size)
{
    struct counts *c = user;
    struct tw_gltf_scene *scene = NULL;
    const struct tw_gltf_settings limits = {16u << 20, 1u << 20};
    if (tw_gltf_import_memory(data, size, path, NULL, &limits, NULL, &scene) == 0)
        c->imported_memory++;
    tw_gltf_scene_destroy(scene);
    scene = NULL;
    LLVMFuzzerTestOneInput(data, size);
    if (tw_gltf_import(path, &limits, NULL, &scene) == 0) {
        c->imported_path++;
        exercise(scene);
    }
    tw_gltf_scene_destroy(scene);
}

int main(int argc, char **argv)
{
    struct counts c = {0};
    struct fuzz_driver d = {.target = "fuzz-gltf", .run = run_input, .user = &c};
    const int rc = fuzz_driver_main(argc, argv, &d);
    if (rc == 0)
        printf("fuzz-gltf: %u imported from memory, %u by path\n", c.imported_memory,
               c.imported_path);
    return rc;
}
#endif
