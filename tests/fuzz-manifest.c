/* Fuzz target for tileset manifests: LLVMFuzzerTestOneInput parses the input
 * as a manifest whose files resolve in TW_FUZZ_MANIFEST_DIR (the Kenney city
 * folder, so that valid names load real glTF files). Built with libFuzzer
 * when TW_LIBFUZZER is defined; otherwise a plain main runs the inputs named
 * on the command line (files, or folders walked recursively). */
#include "tileworld/tilesets.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef TW_FUZZ_MANIFEST_DIR
#define TW_FUZZ_MANIFEST_DIR "."
#endif

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static int parse(const uint8_t *data, size_t size)
{
    struct tw_tileset *ts = NULL;
    const struct tw_manifest_settings limits = {256, {16u << 20, 1u << 20}};
    const int err = tw_tilesets_parse_manifest((const char *)data, size, "fuzz.json",
                                               TW_FUZZ_MANIFEST_DIR, &limits, NULL, &ts);
    tw_tileset_destroy(ts);
    return err;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    parse(data, size);
    return 0;
}

#ifndef TW_LIBFUZZER
#include "tests/fuzz-driver.h"
#include "tiles/tiles-internal.h"

static void run_input(void *user, const char *path, const uint8_t *data, size_t size)
{
    unsigned *loaded = user;
    (void)path;
    if (parse(data, size) == 0)
        ++*loaded;
}

int main(int argc, char **argv)
{
    unsigned loaded = 0;
    struct fuzz_driver d = {.target = "fuzz-manifest", .run = run_input, .user = &loaded};
    const int rc = fuzz_driver_main(argc, argv, &d);
    if (rc == 0)
        printf("fuzz-manifest: %u loaded\n", loaded);
    return rc;
}
#endif
