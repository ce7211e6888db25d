/*
 * Output files that never lie: each is written under a temporary name in
 * its own folder (DIR/.NAME.tmp) and renamed to DIR/NAME only once it is
 * complete, so that a reader, or a run killed half-way, never leaves a
 * half-written file under a final name. Every write is checked; the first
 * failure is kept and reported as one line "DIR/NAME: cannot write: reason".
 *
 * No fsync: the rename makes a file whole against a killed process, not
 * against a machine that loses power, and syncing between frames would
 * show up in the frame times being measured.
 */
#ifndef TW_TOOLS_OUTFILE_H
#define TW_TOOLS_OUTFILE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#define TW_OUTFILE_PATH 1200

struct tw_outfile {
    FILE *f;                        /* NULL when closed */
    char path[TW_OUTFILE_PATH];     /* the final name */
    char tmp[TW_OUTFILE_PATH];      /* the temporary name it is written under */
    int error;                      /* errno of the first failed write, 0 while none */
};

/* The temporary name of path: DIR/.NAME.tmp. Returns false when it does not
 * fit in size bytes. */
bool tw_outfile_tmp_name(const char *path, char *out, size_t size);

/* Creates path's temporary (replacing one a killed run left). On failure
 * writes "PATH: cannot write: reason" into err and returns TW_ERR_IO. */
int tw_outfile_open(struct tw_outfile *o, const char *path, char *err, size_t err_size);

/* The same under a temporary name of this process's own, DIR/.NAME.tmp.PID:
 * for files that several processes may write into one folder at once (a
 * bake's shards), where one's temporary must not be another's. What a
 * killed process leaves is not replaced. */
int tw_outfile_open_unique(struct tw_outfile *o, const char *path, char *err, size_t err_size);

/* Formatted and raw writes. false once a write has failed (then nothing
 * more is written; tw_outfile_commit reports it). */
bool tw_outfile_printf(struct tw_outfile *o, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
bool tw_outfile_write(struct tw_outfile *o, const void *data, size_t size);

/* The message of the first failed write: "PATH: cannot write: reason".
 * Returns TW_ERR_IO. */
int tw_outfile_report(const struct tw_outfile *o, char *err, size_t err_size);

/* Flushes and closes the file and renames it to its final name. On any
 * failure, now or in an earlier write, removes the temporary and returns
 * TW_ERR_IO with the message in err. */
int tw_outfile_commit(struct tw_outfile *o, char *err, size_t err_size);

/* Closes and removes the temporary, leaving no file (after a failure
 * elsewhere). A closed or zeroed o is left alone. */
void tw_outfile_discard(struct tw_outfile *o);

/* Writes size bytes at data as path, whole or not at all. */
int tw_outfile_write_all(const char *path, const void *data, size_t size, char *err,
                         size_t err_size);

/* Writes an RGB8 image (top row first) as a PNG file, whole or not at all. */
int tw_outfile_write_png(const char *path, const uint8_t *rgb, uint32_t width, uint32_t height,
                         char *err, size_t err_size);

#endif
