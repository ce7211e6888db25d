/* The headless contexts (context.h): EGL (device or surfaceless platform)
 * and OSMesa, each library loaded when first asked for. */
#include "tiles/tiles-internal.h"
#include "tileworld/context.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/osmesa.h>
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>

/* EGL 1.5 and EGL_KHR_create_context names, spelled out for older headers. */
#ifndef EGL_CONTEXT_MAJOR_VERSION
#define EGL_CONTEXT_MAJOR_VERSION 0x3098
#endif
#ifndef EGL_CONTEXT_MINOR_VERSION
#define EGL_CONTEXT_MINOR_VERSION 0x30FB
#endif
#ifndef EGL_CONTEXT_OPENGL_PROFILE_MASK
#define EGL_CONTEXT_OPENGL_PROFILE_MASK 0x30FD
#endif
#ifndef EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT
#define EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT 0x00000001
#endif

#define MAX_DEVICES 16

/* The versions tried, highest first: the first the driver gives is kept. */
static const int gl_versions[][2] = {
    {4, 6}, {4, 5}, {4, 4}, {4, 3}, {4, 2}, {4, 1}, {4, 0}, {3, 3},
};
enum { GL_VERSION_COUNT = sizeof(gl_versions) / sizeof(gl_versions[0]) };

/* ---- the libraries, loaded once per process ---------------------------------------
 * The entry points of a loaded library never change, so they are kept once
 * for every context, and the library stays loaded: llvmpipe's threads and
 * glvnd's dispatch outlive any one context. */

struct egl_api {
    bool loaded;
    char error[256];
    PFNEGLGETPROCADDRESSPROC GetProcAddress;
    PFNEGLQUERYSTRINGPROC QueryString;
    PFNEGLGETERRORPROC GetError;
    PFNEGLINITIALIZEPROC Initialize;
    PFNEGLBINDAPIPROC BindAPI;
    PFNEGLCHOOSECONFIGPROC ChooseConfig;
    PFNEGLCREATECONTEXTPROC CreateContext;
    PFNEGLDESTROYCONTEXTPROC DestroyContext;
    PFNEGLCREATEPBUFFERSURFACEPROC CreatePbufferSurface;
    PFNEGLDESTROYSURFACEPROC DestroySurface;
    PFNEGLMAKECURRENTPROC MakeCurrent;
    PFNEGLGETCURRENTCONTEXTPROC GetCurrentContext;
    PFNEGLRELEASETHREADPROC ReleaseThread;
    /* client extensions, absent where the library lacks them */
    PFNEGLGETPLATFORMDISPLAYEXTPROC GetPlatformDisplayEXT;
    PFNEGLQUERYDEVICESEXTPROC QueryDevicesEXT;
    PFNEGLQUERYDEVICESTRINGEXTPROC QueryDeviceStringEXT;
};

struct osmesa_api {
    bool loaded;
    char error[256];
    OSMesaContext (*CreateContextAttribs)(const int *attribs, OSMesaContext share);
    GLboolean (*MakeCurrent)(OSMesaContext c, void *buffer, GLenum type, GLsizei w, GLsizei h);
    void (*DestroyContext)(OSMesaContext c);
    OSMESAproc (*GetProcAddress)(const char *name);
    OSMesaContext (*GetCurrentContext)(void);
};

static struct egl_api egl;
static struct osmesa_api osmesa;
static pthread_once_t egl_once = PTHREAD_ONCE_INIT;
static pthread_once_t osmesa_once = PTHREAD_ONCE_INIT;

/* dlsym's object pointer to a function pointer, as every GL loader does
 * (POSIX guarantees the conversion). */
#define LOAD_SYM(lib, api, name, symbol) \
    do { \
        void *p_ = dlsym(lib, symbol); \
        memcpy(&(api).name, &p_, sizeof(p_)); \
    } while (0)

static bool has_word(const char *list, const char *word)
{
    const size_t n = strlen(word);
    for (const char *s = list; s && (s = strstr(s, word)) != NULL; s += n)
        if ((s == list || s[-1] == ' ') && (s[n] == ' ' || s[n] == '\0'))
            return true;
    return false;
}

static void load_egl(void)
{
    void *lib = dlopen("libEGL.so.1", RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        snprintf(egl.error, sizeof(egl.error), "libEGL.so.1 cannot be loaded (%s)", dlerror());
        return;
    }
    LOAD_SYM(lib, egl, GetProcAddress, "eglGetProcAddress");
    LOAD_SYM(lib, egl, QueryString, "eglQueryString");
    LOAD_SYM(lib, egl, GetError, "eglGetError");
    LOAD_SYM(lib, egl, Initialize, "eglInitialize");
    LOAD_SYM(lib, egl, BindAPI, "eglBindAPI");
    LOAD_SYM(lib, egl, ChooseConfig, "eglChooseConfig");
    LOAD_SYM(lib, egl, CreateContext, "eglCreateContext");
    LOAD_SYM(lib, egl, DestroyContext, "eglDestroyContext");
    LOAD_SYM(lib, egl, CreatePbufferSurface, "eglCreatePbufferSurface");
    LOAD_SYM(lib, egl, DestroySurface, "eglDestroySurface");
    LOAD_SYM(lib, egl, MakeCurrent, "eglMakeCurrent");
    LOAD_SYM(lib, egl, GetCurrentContext, "eglGetCurrentContext");
    LOAD_SYM(lib, egl, ReleaseThread, "eglReleaseThread");
    if (!egl.GetProcAddress || !egl.QueryString || !egl.GetError || !egl.Initialize ||
        !egl.BindAPI || !egl.ChooseConfig || !egl.CreateContext || !egl.DestroyContext ||
        !egl.CreatePbufferSurface || !egl.DestroySurface || !egl.MakeCurrent ||
        !egl.GetCurrentContext || !egl.ReleaseThread) {
        snprintf(egl.error, sizeof(egl.error), "libEGL.so.1 lacks EGL 1.4's entry points");
        return;
    }
    const char *client = egl.QueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    if (has_word(client, "EGL_EXT_platform_base")) {
        void *p = egl.GetProcAddress("eglGetPlatformDisplayEXT");
        memcpy(&egl.GetPlatformDisplayEXT, &p, sizeof(p));
    }
    if (has_word(client, "EGL_EXT_device_enumeration") || has_word(client, "EGL_EXT_device_base")) {
        void *p = egl.GetProcAddress("eglQueryDevicesEXT");
        memcpy(&egl.QueryDevicesEXT, &p, sizeof(p));
    }
    if (has_word(client, "EGL_EXT_device_query") || has_word(client, "EGL_EXT_device_base")) {
        void *p = egl.GetProcAddress("eglQueryDeviceStringEXT");
        memcpy(&egl.QueryDeviceStringEXT, &p, sizeof(p));
    }
    egl.loaded = true;
}

static void load_osmesa(void)
{
    void *lib = dlopen("libOSMesa.so.8", RTLD_NOW | RTLD_LOCAL);
    if (!lib)
        lib = dlopen("libOSMesa.so.6", RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        snprintf(osmesa.error, sizeof(osmesa.error), "libOSMesa.so.8 cannot be loaded (%s)",
                 dlerror());
        return;
    }
    LOAD_SYM(lib, osmesa, CreateContextAttribs, "OSMesaCreateContextAttribs");
    LOAD_SYM(lib, osmesa, MakeCurrent, "OSMesaMakeCurrent");
    LOAD_SYM(lib, osmesa, DestroyContext, "OSMesaDestroyContext");
    LOAD_SYM(lib, osmesa, GetProcAddress, "OSMesaGetProcAddress");
    LOAD_SYM(lib, osmesa, GetCurrentContext, "OSMesaGetCurrentContext");
    if (!osmesa.CreateContextAttribs || !osmesa.MakeCurrent || !osmesa.DestroyContext ||
        !osmesa.GetProcAddress || !osmesa.GetCurrentContext) {
        snprintf(osmesa.error, sizeof(osmesa.error),
                 "libOSMesa lacks OSMesaCreateContextAttribs (Mesa 10 or later)");
        return;
    }
    osmesa.loaded = true;
}

static void *egl_get_proc(const char *name)
{
    void (*f)(void) = egl.GetProcAddress(name);
    void *p;
    memcpy(&p, &f, sizeof(p));
    return p;
}

static void *osmesa_get_proc(const char *name)
{
    OSMESAproc f = osmesa.GetProcAddress(name);
    void *p;
    memcpy(&p, &f, sizeof(p));
    return p;
}

/* ---- the context ------------------------------------------------------------------ */

enum kind { KIND_OSMESA, KIND_EGL_DEVICE, KIND_EGL_SURFACELESS };

static const char *const kind_names[] = {"osmesa", "egl-device", "egl-surfaceless"};

struct tw_context {
    enum kind kind;
    uint32_t width, height;
    struct tw_log log;
    /* OSMesa */
    OSMesaContext osmesa;
    void *buffer;          /* OSMesa's default framebuffer; the library renders to an FBO */
    /* EGL */
    EGLDisplay display;
    EGLContext context;
    EGLSurface surface;    /* a 1x1 pbuffer, or EGL_NO_SURFACE where surfaceless works */
    int32_t device_index;
    char device[256];
    /* what it is */
    char vendor[128], renderer[256], version[128];
    uint32_t gl_major, gl_minor;
    bool software;
};

/* What was tried and why it failed, for the one error line. */
struct attempts {
    char text[1024];
    size_t len;
};

static void tried(struct attempts *a, const char *fmt, ...)
{
    char one[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(one, sizeof(one), fmt, ap);
    va_end(ap);
    const int n = snprintf(a->text + a->len, sizeof(a->text) - a->len, "%s%s",
                           a->len ? "; " : "", one);
    a->len += n > 0 ? (size_t)n : 0;
    if (a->len >= sizeof(a->text))
        a->len = sizeof(a->text) - 1;   /* cut: the text is full */
}
/* Reads what the current context is; false if it is not a 3.3+ context at
 * all (a driver that ignored the version asked for). */
static bool read_gl_strings(struct tw_context *c, tw_gl_get_proc_fn get_proc)
{
    typedef const unsigned char *(*get_string_fn)(GLenum);
    typedef void (*get_integer_fn)(GLenum, GLint *);
    get_string_fn get_string;
    get_integer_fn get_integer;
    void *p = get_proc("glGetString");
    memcpy(&get_string, &p, sizeof(p));
    p = get_proc("glGetIntegerv");
    memcpy(&get_integer, &p, sizeof(p));
    if (!get_string || !get_integer)
        return false;
    const char *v = (const char *)get_string(GL_VENDOR);
    const char *r = (const char *)get_string(GL_RENDERER);
    const char *ver = (const char *)get_string(GL_VERSION);
    snprintf(c->vendor, sizeof(c->vendor), "%s", v ? v : "");
    snprintf(c->renderer, sizeof(c->renderer), "%s", r ? r : "");
    snprintf(c->version, sizeof(c->version), "%s", ver ? ver : "");
    GLint major = 0, minor = 0;
    get_integer(0x821B /* GL_MAJOR_VERSION */, &major);
    get_integer(0x821C /* GL_MINOR_VERSION */, &minor);
    c->gl_major = major > 0 ? (uint32_t)major : 0;
    c->gl_minor = minor > 0 ? (uint32_t)minor : 0;
    c->software = tw_renderer_name_is_software(c->renderer);
    return major > 3 || (major == 3 && minor >= 3);
}

static const char *egl_error_name(EGLint e)
{
    switch (e) {
    case EGL_SUCCESS: return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED: return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS: return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC: return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE: return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG: return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT: return "EGL_BAD_CONTEXT";
    case EGL_BAD_DISPLAY: return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH: return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER: return "EGL_BAD_PARAMETER";
    case EGL_BAD_SURFACE: return "EGL_BAD_SURFACE";
    default: return "an EGL error";
    }
}

static void egl_release(struct tw_context *c)
{
    if (c->context != EGL_NO_CONTEXT) {
        if (egl.GetCurrentContext() == c->context)
            egl.MakeCurrent(c->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
        egl.DestroyContext(c->display, c->context);
        c->context = EGL_NO_CONTEXT;
    }
    if (c->surface != EGL_NO_SURFACE) {
        egl.DestroySurface(c->display, c->surface);
        c->surface = EGL_NO_SURFACE;
    }
    /* The display is not terminated: EGL displays are one per device and
     * process, and another context may be using it. */
}

/* Makes a core context on an initialised display and makes it current;
 * false with a reason in why. */
static bool egl_make_context(struct tw_context *c, EGLDisplay dpy, char *why, size_t why_size)
{
    EGLint major = 0, minor = 0;
    if (!egl.Initialize(dpy, &major, &minor)) {
        snprintf(why, why_size, "eglInitialize failed (%s)", egl_error_name(egl.GetError()));
        return false;
    }
    c->display = dpy;
    const char *ext = egl.QueryString(dpy, EGL_EXTENSIONS);
    const bool surfaceless = has_word(ext, "EGL_KHR_surfaceless_context");
    if (!(major > 1 || minor >= 5) && !has_word(ext, "EGL_KHR_create_context")) {
        snprintf(why, why_size, "EGL %d.%d without EGL_KHR_create_context", major, minor);
        return false;
    }
    if (!egl.BindAPI(EGL_OPENGL_API)) {
        snprintf(why, why_size, "no desktop OpenGL (eglBindAPI: %s)",
                 egl_error_name(egl.GetError()));
        return false;
    }
    const EGLint config_attribs[] = {
        EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT,
        EGL_SURFACE_TYPE, surfaceless ? EGL_DONT_CARE : EGL_PBUFFER_BIT,
        EGL_NONE,
    };
    EGLConfig config;
    EGLint count = 0;
    if (!egl.ChooseConfig(dpy, config_attribs, &config, 1, &count) || count < 1) {
        snprintf(why, why_size, "no config for desktop OpenGL%s",
                 surfaceless ? "" : " with a pbuffer");
        return false;
    }
    for (int k = 0; k < GL_VERSION_COUNT && c->context == EGL_NO_CONTEXT; k++) {
        const EGLint attribs[] = {
            EGL_CONTEXT_MAJOR_VERSION, gl_versions[k][0],
            EGL_CONTEXT_MINOR_VERSION, gl_versions[k][1],
            EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
            EGL_NONE,
        };
        c->context = egl.CreateContext(dpy, config, EGL_NO_CONTEXT, attribs);
    }
    if (c->context == EGL_NO_CONTEXT) {
        snprintf(why, why_size, "no OpenGL 3.3 core context (%s)", egl_error_name(egl.GetError()));
        return false;
    }
    if (!surfaceless) {
        const EGLint pbuffer_attribs[] = {EGL_WIDTH, 1, EGL_HEIGHT, 1, EGL_NONE};
        c->surface = egl.CreatePbufferSurface(dpy, config, pbuffer_attribs);
        if (c->surface == EGL_NO_SURFACE) {
            snprintf(why, why_size, "no pbuffer (%s)", egl_error_name(egl.GetError()));
            egl_release(c);
            return false;
        }
    }
    if (!egl.MakeCurrent(dpy, c->surface, c->surface, c->context)) {
        snprintf(why, why_size, "eglMakeCurrent failed (%s)", egl_error_name(egl.GetError()));
        egl_release(c);
        return false;
    }
    if (!read_gl_strings(c, egl_get_proc)) {
        snprintf(why, why_size, "the driver made an OpenGL %u.%u context, not 3.3 core",
                 c->gl_major, c->gl_minor);
        egl_release(c);
        return false;
    }
    return true;
}

static bool device_is_software(EGLDeviceEXT dev)
{
    const char *ext = egl.QueryDeviceStringEXT ? egl.QueryDeviceStringEXT(dev, EGL_EXTENSIONS)
                                               : NULL;
    return has_word(ext, "EGL_MESA_device_software");
}

static void describe_device(struct tw_context *c, EGLDeviceEXT dev)
{
    const char *node = NULL;
    if (egl.QueryDeviceStringEXT) {
        const char *ext = egl.QueryDeviceStringEXT(dev, EGL_EXTENSIONS);
        if (has_word(ext, "EGL_EXT_device_drm"))
            node = egl.QueryDeviceStringEXT(dev, EGL_DRM_DEVICE_FILE_EXT);
        if (!node)
            node = ext;
    }
    snprintf(c->device, sizeof(c->device), "%s", node ? node : "");
}

/* Tries device `index`; software devices only when allow_software. */
static bool try_device(struct tw_context *c, EGLDeviceEXT dev, int index, bool allow_software,
                       struct attempts *a)
{
    char why[256];
    EGLDisplay dpy = egl.GetPlatformDisplayEXT(EGL_PLATFORM_DEVICE_EXT, dev, NULL);
    if (dpy == EGL_NO_DISPLAY) {
        tried(a, "EGL device %d: no display (%s)", index, egl_error_name(egl.GetError()));
        return false;
    }
    if (!egl_make_context(c, dpy, why, sizeof(why))) {
        tried(a, "EGL device %d: %s", index, why);
        c->display = EGL_NO_DISPLAY;
        return false;
    }
    if (c->software && !allow_software) {
        tried(a, "EGL device %d: a software renderer (%s)", index, c->renderer);
        egl_release(c);
        c->display = EGL_NO_DISPLAY;
        return false;
    }
    c->kind = KIND_EGL_DEVICE;
    c->device_index = index;
    describe_device(c, dev);
    return true;
}

static bool egl_ready(struct attempts *a)
{
    pthread_once(&egl_once, load_egl);
    if (!egl.loaded)
        tried(a, "EGL: %s", egl.error);
    return egl.loaded;
}

/* The device platform: the picked device, or the hardware ones in order
 * (with software, the software ones too). */
static bool try_devices(struct tw_context *c, const struct tw_context_settings *s, bool software,
                        struct attempts *a)
{
    if (!egl.QueryDevicesEXT || !egl.GetPlatformDisplayEXT) {
        tried(a, "EGL device platform: libEGL lacks EGL_EXT_device_enumeration or "
                 "EGL_EXT_platform_device");
        return false;
    }
    EGLDeviceEXT devices[MAX_DEVICES];
    EGLint n = 0;
    if (!egl.QueryDevicesEXT(MAX_DEVICES, devices, &n))
        n = 0;
    if (s->pick_device) {
        if (s->device >= (uint32_t)n) {
            tried(a, "EGL device %u: no such device (%d EGL device%s)", s->device, (int)n,
                  n == 1 ? "" : "s");
            return false;
        }
        return try_device(c, devices[s->device], (int)s->device, true, a);
    }
    int hardware = 0;
    for (EGLint k = 0; k < n; k++) {
        if (device_is_software(devices[k]) != software)
            continue;
        hardware += !software;
        if (try_device(c, devices[k], (int)k, software, a))
            return true;
    }
    if (!software && hardware == 0)
        tried(a, "EGL device platform: no GPU among %d device%s", (int)n, n == 1 ? "" : "s");
    return false;
}

static bool try_surfaceless(struct tw_context *c, struct attempts *a)
{
    const char *client = egl.QueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    if (!egl.GetPlatformDisplayEXT || !has_word(client, "EGL_MESA_platform_surfaceless")) {
        tried(a, "EGL surfaceless platform: not offered (EGL_MESA_platform_surfaceless)");
        return false;
    }
    EGLDisplay dpy = egl.GetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY,
                                               NULL);
    char why[256];
    if (dpy == EGL_NO_DISPLAY) {
        tried(a, "EGL surfaceless platform: no display (%s)", egl_error_name(egl.GetError()));
        return false;
    }
    if (!egl_make_context(c, dpy, why, sizeof(why))) {
        tried(a, "EGL surfaceless platform: %s", why);
        c->display = EGL_NO_DISPLAY;
        return false;
    }
    c->kind = KIND_EGL_SURFACELESS;
    return true;
}

static bool try_osmesa(struct tw_context *c, struct attempts *a)
{
    pthread_once(&osmesa_once, load_osmesa);
    if (!osmesa.loaded) {
        tried(a, "OSMesa: %s", osmesa.error);
        return false;
    }
    for (int k = 0; k < GL_VERSION_COUNT && !c->osmesa; k++) {
        const int attribs[] = {
            OSMESA_FORMAT, OSMESA_RGBA,
            OSMESA_DEPTH_BITS, 24,
            OSMESA_PROFILE, OSMESA_CORE_PROFILE,
            OSMESA_CONTEXT_MAJOR_VERSION, gl_versions[k][0],
            OSMESA_CONTEXT_MINOR_VERSION, gl_versions[k][1],
            0,
        };
        c->osmesa = osmesa.CreateContextAttribs(attribs, NULL);
    }
    if (!c->osmesa) {
        tried(a, "OSMesa: no OpenGL 3.3 core context");
        return false;
    }
    c->kind = KIND_OSMESA;
    c->buffer = calloc((size_t)c->width * c->height, 4);
    if (!c->buffer || !osmesa.MakeCurrent(c->osmesa, c->buffer, GL_UNSIGNED_BYTE,
                                          (GLsizei)c->width, (GLsizei)c->height)) {
        tried(a, c->buffer ? "OSMesa: the context cannot be made current"
                             : "OSMesa: out of memory");
        goto fail;
    }
    if (!read_gl_strings(c, osmesa_get_proc)) {
        tried(a, "OSMesa: made an OpenGL %u.%u context, not 3.3 core", c->gl_major, c->gl_minor);
        goto fail;
    }
    return true;
fail:
    osmesa.DestroyContext(c->osmesa);
    c->osmesa = NULL;
    free(c->buffer);
    c->buffer = NULL;
    return false;
}

const char *tw_context_api_name(enum tw_context_api api)
{
    switch (api) {
    case TW_CONTEXT_AUTO: return "auto";
    case TW_CONTEXT_EGL: return "egl";
    case TW_CONTEXT_OSMESA: return "osmesa";
    default: return NULL;
    }
}

/* The least address space (RLIMIT_AS, `ulimit -v`) a context is tried in.
 * Measured at 640 x 360 on llvmpipe (2 cores): a context takes about 570 MiB
 * when nothing limits it, and a world about 60 MiB more plus 128 MiB of
 * reservations per BVH builder; no walk succeeded below about 760 MiB, and
 * below 512 MiB the driver crashed (SIGSEGV) as often as it failed. A
 * driver that crashes cannot be recovered from: below this it is not
 * asked. */
#define MIN_ADDRESS_SPACE_MIB 512u

/* The process's address-space limit in MiB, 0 if none. */
static unsigned long long address_space_limit_mib(void)
{
    struct rlimit rl;
    if (getrlimit(RLIMIT_AS, &rl) != 0 || rl.rlim_cur == RLIM_INFINITY)
        return 0;
    return (unsigned long long)rl.rlim_cur >> 20;
}

int tw_context_create(const struct tw_context_settings *s, struct tw_context **out)
{
    if (!s || !out || s->width == 0 || s->height == 0 || s->width > 16384 ||
        s->height > 16384 || !tw_context_api_name(s->api))
        return TW_ERR_INVALID;
    if (s->pick_device && s->api == TW_CONTEXT_OSMESA) {
        tw_log_printf(&s->log, TW_LOG_ERROR,
                      "an EGL device (device %u) was asked for with OSMesa, which has none",
                      s->device);
        return TW_ERR_INVALID;
    }
    const unsigned long long limit_mib = address_space_limit_mib();
    if (limit_mib > 0 && limit_mib < MIN_ADDRESS_SPACE_MIB) {
        tw_log_printf(&s->log, TW_LOG_ERROR,
                      "no OpenGL context under an address-space limit of %llu MiB (ulimit -v): "
                      "one needs %u MiB at the least (a world drawn with the software "
                      "rasteriser, about 800 MiB): raise the limit",
                      limit_mib, MIN_ADDRESS_SPACE_MIB);
        return TW_ERR_NOMEM;
    }
    struct tw_context *c = calloc(1, sizeof(*c));
    if (!c) {
        tw_log_printf(&s->log, TW_LOG_ERROR, "no OpenGL context: out of memory");
        return TW_ERR_NOMEM;
    }
    c->log = s->log;
    c->width = s->width;
    c->height = s->height;
    c->display = EGL_NO_DISPLAY;
    c->context = EGL_NO_CONTEXT;
    c->surface = EGL_NO_SURFACE;
    c->device_index = -1;
    struct attempts a = {0};
    bool ok = false;
    if (s->pick_device) {
        ok = egl_ready(&a) && try_devices(c, s, false, &a);
    } else if (s->api == TW_CONTEXT_OSMESA) {
        ok = try_osmesa(c, &a);
    } else if (s->api == TW_CONTEXT_EGL) {
        ok = egl_ready(&a) && (try_devices(c, s, false, &a) || try_surfaceless(c, &a) ||
                               try_devices(c, s, true, &a));
    } else {
        /* auto: a GPU if there is one; else OSMesa, whose images the tests
         * were made with; else what EGL has in software. */
        const bool have_egl = egl_ready(&a);
        ok = (have_egl && try_devices(c, s, false, &a)) || try_osmesa(c, &a) ||
             (have_egl && (try_surfaceless(c, &a) || try_devices(c, s, true, &a)));
    }
    if (!ok) {
        char hint[160] = "";
        if (limit_mib > 0)
            snprintf(hint, sizeof(hint), " (under an address-space limit of %llu MiB, ulimit -v: "
                     "most likely out of memory)", limit_mib);
        tw_log_printf(&c->log, TW_LOG_ERROR, "no OpenGL 3.3 core context (--gl %s%s): %s%s",
                      tw_context_api_name(s->api), s->pick_device ? ", a picked device" : "",
                      a.text, hint);
        tw_context_destroy(c);
        return TW_ERR_GL;
    }
    *out = c;
    return TW_OK;
}

int tw_context_create_headless(uint32_t width, uint32_t height, const struct tw_log *log,
                               struct tw_context **out)
{
    struct tw_context_settings s = {.width = width, .height = height};
    if (log)
        s.log = *log;
    return tw_context_create(&s, out);
}

void tw_context_describe(const struct tw_context *c, struct tw_context_info *out)
{
    if (!out)
        return;
    memset(out, 0, sizeof(*out));
    out->device_index = -1;
    if (!c)
        return;
    out->kind = kind_names[c->kind];
    out->vendor = c->vendor;
    out->renderer = c->renderer;
    out->version = c->version;
    out->device = c->device;
    out->device_index = c->device_index;
    out->gl_major = c->gl_major;
    out->gl_minor = c->gl_minor;
    out->software = c->software;
}

tw_gl_get_proc_fn tw_context_get_proc(const struct tw_context *c)
{
    if (!c)
        return NULL;
    return c->kind == KIND_OSMESA ? osmesa_get_proc : egl_get_proc;
}

int tw_context_make_current(struct tw_context *c)
{
    if (!c)
        return TW_ERR_INVALID;
    if (c->kind == KIND_OSMESA) {
        if (!osmesa.MakeCurrent(c->osmesa, c->buffer, GL_UNSIGNED_BYTE, (GLsizei)c->width,
                                (GLsizei)c->height)) {
            tw_log_printf(&c->log, TW_LOG_ERROR, "the OSMesa context cannot be made current");
            return TW_ERR_GL;
        }
        return TW_OK;
    }
    if (!egl.MakeCurrent(c->display, c->surface, c->surface, c->context)) {
        tw_log_printf(&c->log, TW_LOG_ERROR, "the EGL context cannot be made current (%s)",
                      egl_error_name(egl.GetError()));
        return TW_ERR_GL;
    }
    return TW_OK;
}

int tw_context_release(struct tw_context *c)
{
    if (!c)
        return TW_ERR_INVALID;
    if (c->kind == KIND_OSMESA) {
        if (osmesa.GetCurrentContext() == c->osmesa &&
            !osmesa.MakeCurrent(NULL, NULL, GL_UNSIGNED_BYTE, 0, 0)) {
            tw_log_printf(&c->log, TW_LOG_ERROR, "the OSMesa context cannot be released");
            return TW_ERR_GL;
        }
        return TW_OK;
    }
    if (egl.GetCurrentContext() == c->context &&
        !egl.MakeCurrent(c->display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT)) {
        tw_log_printf(&c->log, TW_LOG_ERROR, "the EGL context cannot be released (%s)",
                      egl_error_name(egl.GetError()));
        return TW_ERR_GL;
    }
    return TW_OK;
}

void tw_context_destroy(struct tw_context *c)
{
    if (!c)
        return;
    if (c->osmesa)
        osmesa.DestroyContext(c->osmesa);
    if (c->display != EGL_NO_DISPLAY) {
        egl_release(c);
        egl.ReleaseThread();
    }
    free(c->buffer);
    free(c);
}
