/*
 * What build this program is, for the reports and `tileworld info`: the
 * commit it was built from (git describe --always --dirty at build time,
 * "unknown" outside a git checkout) and meson's build type ("release",
 * "debugoptimized", ...). Both strings are static.
 */
#ifndef TW_TOOLS_BUILDINFO_H
#define TW_TOOLS_BUILDINFO_H

const char *tw_build_commit(void);
const char *tw_build_type(void);

#endif
