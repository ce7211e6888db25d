/*
 * The plain-main driver of a fuzz target built without libFuzzer: runs
 * LLVMFuzzerTestOneInput() on every file named on the command line (folders
 * are walked recursively, in name order). A path that does not exist is
 * skipped (a corpus in ../shared may be absent); if no input was found at
 * all, it exits 77, meson's "skipped". A
 * target includes it after defining LLVMFuzzerTestOneInput() and calls
 * fuzz_driver_main() from its main().
 */
#ifndef TW_TESTS_FUZZ_DRIVER_H
#define TW_TESTS_FUZZ_DRIVER_H

#include <dirent.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static void fuzz_driver_file(const char *target, const char *path, unsigned *inputs)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        fprintf(stderr, "%s: cannot open %s\n", target, path);
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
        fprintf(stderr, "%s: out of memory reading %s\n", target, path);
        exit(2);
    }
    LLVMFuzzerTestOneInput(data, size);
    free(data);
    ++*inputs;
}

static void fuzz_driver_path(const char *target, const char *path, unsigned *inputs)
{
    struct stat st;
    if (stat(path, &st) != 0) {
        /* A corpus outside the tree (../shared) may be absent: skipped. */
        fprintf(stderr, "%s: %s does not exist: skipped\n", target, path);
        return;
    }
    if (!S_ISDIR(st.st_mode)) {
        fuzz_driver_file(target, path, inputs);
        return;
    }
    struct dirent **entries = NULL;
    const int n = scandir(path, &entries, NULL, alphasort);
    if (n < 0) {
        fprintf(stderr, "%s: cannot list %s\n", target, path);
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
            fuzz_driver_path(target, child, inputs);
            free(child);
        }
        free(entries[k]);
    }
    free(entries);
}

static int fuzz_driver_main(int argc, char **argv, const char *target)
{
    if (argc < 2) {
        fprintf(stderr, "usage: %s FILE|FOLDER...\n", target);
        return 2;
    }
    unsigned inputs = 0;
    for (int k = 1; k < argc; k++)
        fuzz_driver_path(target, argv[k], &inputs);
    if (inputs == 0) {
        fprintf(stderr, "%s: no inputs found: skipped\n", target);
        return 77;
    }
    printf("%s: %u inputs ran without a crash\n", target, inputs);
    return 0;
}

#endif
