/*
 * The headless contexts' API (context.h): settings refused at the boundary,
 * each way to a context this machine has, what describe says of it, and two
 * contexts of two kinds current in turn on one thread. (test-context-cli.sh
 * renders through each and compares the images.)
 */
#include <string.h>

#include "tests/check.h"
#include "tileworld/context.h"

static int errors_logged;

static void count_log(void *user, enum tw_log_level level, const char *msg)
{
    (void)user;
    (void)msg;
    errors_logged += level == TW_LOG_ERROR;
}

typedef const unsigned char *(*get_string_fn)(unsigned int);

static void refused(void)
{
    struct tw_context *c = (struct tw_context *)&errors_logged; /* must stay untouched */
    struct tw_context *const before = c;
    CHECK(tw_context_create(NULL, &c) == TW_ERR_INVALID);
    struct tw_context_settings s = {.width = 0, .height = 16};
    CHECK(tw_context_create(&s, &c) == TW_ERR_INVALID);
    s.width = 16385;
    CHECK(tw_context_create(&s, &c) == TW_ERR_INVALID);
    s.width = 16;
    s.api = (enum tw_context_api)7;
    CHECK(tw_context_create(&s, &c) == TW_ERR_INVALID);
    s.api = TW_CONTEXT_OSMESA;
    s.pick_device = true;
    s.log = (struct tw_log){count_log, NULL};
    errors_logged = 0;
    CHECK(tw_context_create(&s, &c) == TW_ERR_INVALID);
    CHECK_MSG(errors_logged == 1, "%d error lines", errors_logged);
    /* A device that does not exist: one line, no context. */
    s.api = TW_CONTEXT_EGL;
    s.device = 63;
    errors_logged = 0;
    CHECK(tw_context_create(&s, &c) == TW_ERR_GL);
    CHECK_MSG(errors_logged == 1, "%d error lines", errors_logged);
    CHECK(c == before);
    CHECK(tw_context_make_current(NULL) == TW_ERR_INVALID);
    CHECK(tw_context_get_proc(NULL) == NULL);
    tw_context_destroy(NULL);
    struct tw_context_info ci;
    tw_context_describe(NULL, &ci);
    CHECK(ci.kind == NULL && ci.device_index == -1);
    CHECK(strcmp(tw_context_api_name(TW_CONTEXT_AUTO), "auto") == 0);
    CHECK(strcmp(tw_context_api_name(TW_CONTEXT_EGL), "egl") == 0);
    CHECK(strcmp(tw_context_api_name(TW_CONTEXT_OSMESA), "osmesa") == 0);
    CHECK(tw_context_api_name((enum tw_context_api)3) == NULL);
}

/* A context of api (and device, when pick), checked as describe says it;
 * NULL when this machine has none of that kind (a skip, said). */
static struct tw_context *made(enum tw_context_api api, bool pick)
{
    struct tw_context_settings s = {.width = 64, .height = 48, .api = api, .pick_device = pick};
    struct tw_context *c = NULL;
    if (tw_context_create(&s, &c) != TW_OK) {
        printf("no %s context%s here: not checked\n", tw_context_api_name(api),
               pick ? " on device 0" : "");
        return NULL;
    }
    struct tw_context_info ci;
    tw_context_describe(c, &ci);
    printf("%s%s: %s, %s, %s, GL %u.%u\n", tw_context_api_name(api), pick ? " --gpu 0" : "",
           ci.kind, ci.renderer, ci.version, ci.gl_major, ci.gl_minor);
    CHECK(ci.kind != NULL);
    if (!ci.kind)
        return c;
    if (api == TW_CONTEXT_OSMESA)
        CHECK(strcmp(ci.kind, "osmesa") == 0);
    if (api == TW_CONTEXT_EGL)
        CHECK(strncmp(ci.kind, "egl-", 4) == 0);
    if (pick)
        CHECK(strcmp(ci.kind, "egl-device") == 0 && ci.device_index == 0);
    else if (strcmp(ci.kind, "egl-device") != 0)
        CHECK(ci.device_index == -1);
    CHECK(ci.gl_major > 3 || (ci.gl_major == 3 && ci.gl_minor >= 3));
    CHECK(ci.renderer[0] != '\0' && ci.vendor[0] != '\0' && ci.version[0] != '\0');
    if (strstr(ci.renderer, "llvmpipe") || strstr(ci.renderer, "softpipe"))
        CHECK(ci.software);
    /* The loader is the context's: glGetString answers what describe said. */
    void *p = tw_context_get_proc(c)("glGetString");
    CHECK(p != NULL);
    if (p) {
        get_string_fn get_string;
        memcpy(&get_string, &p, sizeof(p));
        const unsigned char *r = get_string(0x1F01 /* GL_RENDERER */);
        CHECK(r && strcmp((const char *)r, ci.renderer) == 0);
    }
    return c;
}

int main(void)
{
    refused();
    struct tw_context *automatic = made(TW_CONTEXT_AUTO, false);
    CHECK(automatic != NULL);
    tw_context_destroy(automatic);
    struct tw_context *osmesa = made(TW_CONTEXT_OSMESA, false);
    struct tw_context *egl = made(TW_CONTEXT_EGL, false);
    struct tw_context *device = made(TW_CONTEXT_EGL, true);
    CHECK(osmesa || egl);
    /* Two kinds in one process, current in turn. */
    for (int round = 0; round < 2; round++) {
        if (osmesa)
            CHECK(tw_context_make_current(osmesa) == TW_OK);
        if (egl)
            CHECK(tw_context_make_current(egl) == TW_OK);
        if (device)
            CHECK(tw_context_make_current(device) == TW_OK);
    }
    tw_context_destroy(device);
    tw_context_destroy(egl);
    tw_context_destroy(osmesa);
    return check_summary("test-context");
}
