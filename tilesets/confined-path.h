/*
 * Opening a file that a document names relative to its own folder, and
 * keeping it there (private to tilesets/: glTF buffers and images,
 * manifests).
 *
 * A name is first checked as text: it must be a non-empty relative path,
 * not a URI (no "scheme:"), without backslashes, whose ".." never climb above
 * the folder. It is then opened *beneath* the folder's file descriptor in one
 * step, with no window between checking and opening: openat2() with
 * RESOLVE_BENEATH | RESOLVE_NO_MAGICLINKS where the kernel has it (Linux 5.6
 * and later), else a walk that opens one component at a time with
 * openat(O_NOFOLLOW), follows each symbolic link itself (at most 40) and
 * refuses any ".." or link target that would leave the folder. Symbolic
 * links that stay inside are followed; so are mount points. The file read
 * is the one opened: a path is never resolved twice.
 *
 * What neither can tell: a hard link inside the folder to a file elsewhere
 * is that file, by the folder owner's own doing (whoever can make a hard
 * link in the folder could as well copy the file there); a folder shared
 * with someone who may write to it is theirs to fill.
 */
#ifndef TW_TILESETS_CONFINED_PATH_H
#define TW_TILESETS_CONFINED_PATH_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* How the file is looked up: the kernel's openat2() (falling back to the
 * walk when the kernel lacks it, ENOSYS, or a seccomp filter refuses it,
 * EPERM), or always the walk (for tests). */
enum tw_confined_mode {
    TW_CONFINED_AUTO = 0,
    TW_CONFINED_WALK,
};

/* Opens rel, a regular file beneath the folder dir_fd, for reading
 * (O_RDONLY | O_NONBLOCK | O_CLOEXEC: a FIFO is refused, never waited on).
 * On success returns 0 and *out_fd, which the caller closes. On failure
 * returns a negative tw_error (TW_ERR_IO for what the file system says,
 * TW_ERR_FORMAT for a name that is refused as such) and *reason is a static
 * English phrase that completes "\"<rel>\" ...", e.g. "is an absolute path"
 * (strerror() text for other errors). dir_fd is only used during the call. */
int tw_confined_open(int dir_fd, const char *rel, enum tw_confined_mode mode, int *out_fd,
                     const char **reason);

/* The same for the folder that holds rel (rel without its last component:
 * external files named in rel's document resolve there); *out_fd is an
 * O_PATH (or O_RDONLY) descriptor of a folder beneath dir_fd. */
int tw_confined_open_parent(int dir_fd, const char *rel, enum tw_confined_mode mode,
                            int *out_fd, const char **reason);

/* Opens a file the user named (a command-line argument: not confined) the
 * same way: regular files only, never blocking. On failure writes the
 * reason into why ("no such file", "cannot open: <strerror>", "is not a
 * regular file (a FIFO)"). */
int tw_confined_open_user(const char *path, int *out_fd, char *why, size_t why_size);

/* Opens the folder path names, or the folder of the file path names ("."
 * when it has none), as a descriptor to open beneath; -1 with errno set on
 * failure. */
int tw_confined_open_folder(const char *path);
int tw_confined_open_folder_of(const char *path);

/* Reads the whole of the open regular file fd (at most limit bytes) into a
 * malloc()ed block (*data, *size; one spare byte is allocated past the end).
 * On failure the reason is written to why. Does not close fd. */
int tw_confined_read(int fd, uint64_t limit, uint8_t **data, size_t *size, char *why,
                     size_t why_size);

/* The folder part of path ("." when it has none), malloc()ed; NULL when out
 * of memory. */
char *tw_confined_path_dirname(const char *path);

#endif
