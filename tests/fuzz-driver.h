/*
 * The plain-main driver of a fuzz target built without libFuzzer: runs every
 * file named on the command line (folders are walked recursively, in name
 * order). A path that does not exist is skipped (a corpus in ../shared may be
 * absent); if no input was found at all, it exits 77, meson's "skipped". A
 * target includes it after defining LLVMFuzzerTestOneInput() and calls
 * fuzz_driver_main() from its main(), with its own run() where it does more
 * with an input than LLVMFuzzerTestOneInput() does (counts what loads, loads
 * it again by path).
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

struct fuzz_driver {
    const char *target;  /* the program's name, for messages */
    /* Runs one input: the file path, read into data[0, size) (the driver
     * frees it). NULL: LLVMFuzzerTestOneInput(data, size). */
    void (*run)(void *user, const char *path, const uint8_t *data, size_t size);
    void *user;
    unsigned inputs;     /* how many ran */
};

static void fuzz_driver_file(struct fuzz_driver *d, const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        fprintf(stderr, "%s: cannot open %s\n", d->target, path);
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
        fprintf(stderr, "%s: out of memory reading %s\n", d->target, path);
        exit(2);
    }
    if (d->run)
        d->run(d->user, path, data, size);
    else
        LLVMFuzzerTestOneInput(data, size);
    free(data);
    d->inputs++;
}

static void fuzz_driver_path(struct fuzz_driver *d, const char *path)
{
    struct stat st;
    if (stat(path, &st) != 0) {
        /* A corpus outside the tree (../shared) may be absent: skipped. */
        fprintf(stderr, "%s: %s does not exist: skipped\n", d->target, path);
        return;
    }
    if (!S_ISDIR(st.st_mode)) {
        fuzz_driver_file(d, path);
        return;
    }
    struct dirent **entries = NULL;
    const int n = scandir(path, &entries, NULL, alphasort);
    if (n < 0) {
        fprintf(stderr, "%s: cannot list %s\n", d->target, path);
        exit(2);
    }
    for (int k = 0; k < n; k++) {
        const char *name = entries[k]->d_name;
        if (strcmp(name, ".") != 0 && strcmp(name, "..") != 0) {
            const size_t len = strlen(path) + strlen(name) + 2;
            char *child = malloc(len);
            if (!child) {
                fprintf(stderr, "%s: out of memory\n", d->target);
                exit(2);
            }
            snprintf(child, len, "%s/%s", path, name);
            fuzz_driver_path(d, child);
            free(child);
        }
        free(entries[k]);
    }
    free(entries);
}

/* Runs every input named in argv[1..] and says how many ran: 0, 2 for a
 * usage error, or 77 if there was no input at all. */
static int fuzz_driver_main(int argc, char **argv, struct fuzz_driver *d)
{
    if (argc < 2) {
        fprintf(stderr, "usage: %s FILE|FOLDER...\n", d->target);
        return 2;
    }
    for (int k = 1; k < argc; k++)
        fuzz_driver_path(d, argv[k]);
    if (d->inputs == 0) {
        fprintf(stderr, "%s: no inputs found: skipped\n", d->target);
        return 77;
    }
    printf("%s: %u inputs ran without a crash\n", d->target, d->inputs);
    return 0;
}

#endif
