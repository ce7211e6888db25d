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
#include <dirent.h>
#include <sys/stat.h>

struct counts {
    unsigned inputs, loaded;
};

static void run_file(const char *path, struct counts *c)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        fprintf(stderr, "fuzz-manifest: cannot open %s\n", path);
        exit(2);
    }
    size_t cap = 1 << 16, size = 0, n;
    uint8_t *data = malloc(cap);
    while (data && (n = fread(data + size, 1, cap - size, f)) > 0) {
        size += n;
        if (size == cap) {
            uint8_t *grown = realloc(data, cap *= 2);
            if (!grown)
                free(data);
            data = grown;
        }
    }
    fclose(f);
    if (!data) {
        fprintf(stderr, "fuzz-manifest: out of memory reading %s\n", path);
        exit(2);
    }
    c->inputs++;
    if (parse(data, size) == 0)
        c->loaded++;
    free(data);
}

static void run_path(const char *path, struct counts *c)
{
    struct stat st;
    if (stat(path, &st) != 0) {
        /* A corpus in ../shared may be absent: skipped. */
        fprintf(stderr, "fuzz-manifest: %s does not exist: skipped\n", path);
        return;
    }
    if (!S_ISDIR(st.st_mode)) {
        run_file(path, c);
        return;
    }
    struct dirent **entries = NULL;
    const int n = scandir(path, &entries, NULL, alphasort);
    if (n < 0) {
        fprintf(stderr, "fuzz-manifest: cannot list %s\n", path);
        exit(2);
    }
    for (int k = 0; k < n; k++) {
        const char *name = entries[k]->d_name;
        if (strcmp(name, ".") != 0 && strcmp(name, "..") != 0) {
            const size_t len = strlen(path) + strlen(name) + 2;
            char *child = malloc(len);
            if (!child)
                exit(2);
            snprintf(child, len, "%s/%s", path, name);
            run_path(child, c);
            free(child);
        }
        free(entries[k]);
    }
    free(entries);
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: fuzz-manifest FILE|FOLDER...\n");
        return 2;
    }
    struct counts c = {0};
    for (int k = 1; k < argc; k++)
        run_path(argv[k], &c);
    if (c.inputs == 0) {
        fprintf(stderr, "fuzz-manifest: no inputs found: skipped\n");
        return 77;
    }
    printf("fuzz-manifest: %u inputs ran without a crash; %u loaded\n", c.inputs, c.loaded);
    return 0;
}
#endif
