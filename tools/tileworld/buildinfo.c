/* The build's commit and type (buildinfo.h), as meson wrote them. */
#include "tools/tileworld/buildinfo.h"

#include "tools/build-type.h"   /* TW_BUILD_TYPE */
#include "tools/version.h"      /* TW_BUILD_COMMIT */

const char *tw_build_commit(void)
{
    return TW_BUILD_COMMIT[0] ? TW_BUILD_COMMIT : "unknown";
}

const char *tw_build_type(void)
{
    return TW_BUILD_TYPE;
}
