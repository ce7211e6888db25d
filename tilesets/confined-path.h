/*
 * Resolving a file name that a document gives relative to its own folder,
 * and keeping it there (private to tilesets/: glTF buffers, manifests).
 */
#ifndef TW_TILESETS_CONFINED_PATH_H
#define TW_TILESETS_CONFINED_PATH_H

#include <stddef.h>

/* Resolves rel against the folder dir and checks that it names a regular
 * file inside dir: rel must be a non-empty relative path, not a URI (no
 * "scheme:"), without backslashes, whose ".." never climb above dir, and
 * whose real path (symbolic links followed) lies under dir's real path.
 * On success returns 0 and *out is the file's real path (malloc()ed, the
 * caller frees it). On failure returns a negative tw_error and *reason is a
 * static English phrase that completes "\"<rel>\" ...", e.g. "is an absolute
 * path"; errno-based reasons come from strerror. */
int tw_confined_path_resolve(const char *dir, const char *rel, char **out, const char **reason);

/* The folder part of path ("." when it has none), malloc()ed; NULL when out
 * of memory. */
char *tw_confined_path_dirname(const char *path);

#endif
