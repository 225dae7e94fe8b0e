/* A smoke test of a built C core, loaded the way ctypes loads it (LoadLibrary / dlopen by path), for builds
 * this machine cannot load into Python: the Windows DLL under Wine (scripts/build_extension.py runs it).
 *
 *   smoke_core PATH-TO-LIBRARY
 *
 * Checks that the library was built from this contract (RT_CONTRACT_DIGEST) with this SceneDesc layout,
 * then creates an empty scene with a background colour and traces a few rays on two threads: every ray
 * must come back with the background.  Prints "ok" and exits 0, else says what failed and exits 1. */
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "core.h"

#ifdef _WIN32
#include <windows.h>
typedef HMODULE Library;
static Library open_library(const char *path) { return LoadLibraryA(path); }
static void *symbol(Library lib, const char *name) { return (void *)GetProcAddress(lib, name); }
#else
#include <dlfcn.h>
typedef void *Library;
static Library open_library(const char *path) { return dlopen(path, RTLD_NOW); }
static void *symbol(Library lib, const char *name) { return dlsym(lib, name); }
#endif

typedef const char *(*DigestFn)(void);
typedef int64_t (*SizeFn)(int64_t);
typedef int64_t (*LayoutFn)(int64_t, int64_t *, int64_t *, int64_t);
/* SceneDesc is struct 0 of the contract's RT_STRUCTS (rt_struct_size, rt_struct_layout). */
enum { SCENE_DESC = 0 };
#define COUNT_FIELD(type, name) +1
enum { SCENE_DESC_FIELDS = 0 RT_SCENE_DESC_FIELDS(COUNT_FIELD) };
#undef COUNT_FIELD
typedef void *(*CreateFn)(const SceneDesc *, char *, int64_t);
typedef void (*DestroyFn)(void *);
typedef int (*TraceFn)(void *, int64_t, const double *, const double *, double *, int64_t *, int64_t, double, int64_t,
                       int64_t, const int32_t *);

static int fail(const char *what)
{
    printf("smoke_core: %s\n", what);
    return 1;
}

int main(int argc, char **argv)
{
    if (argc != 2)
        return fail("usage: smoke_core PATH-TO-LIBRARY");
    Library lib = open_library(argv[1]);
    if (!lib)
        return fail("the library does not load");
    DigestFn digest = (DigestFn)symbol(lib, "rt_contract_digest");
    SizeFn size = (SizeFn)symbol(lib, "rt_struct_size");
    LayoutFn layout = (LayoutFn)symbol(lib, "rt_struct_layout");
    CreateFn create = (CreateFn)symbol(lib, "rt_create");
    DestroyFn destroy = (DestroyFn)symbol(lib, "rt_destroy");
    TraceFn trace = (TraceFn)symbol(lib, "rt_trace");
    if (!digest || !size || !layout || !create || !destroy || !trace)
        return fail("a function is missing from the library");
    if (strcmp(digest(), RT_CONTRACT_DIGEST) != 0)
        return fail("built from another contract");
    if (size(SCENE_DESC) != (int64_t)sizeof(SceneDesc))
        return fail("SceneDesc has another size");
    int64_t offsets[SCENE_DESC_FIELDS], sizes[SCENE_DESC_FIELDS];
    if (layout(SCENE_DESC, offsets, sizes, SCENE_DESC_FIELDS) != SCENE_DESC_FIELDS)
        return fail("SceneDesc has another number of fields");
    int64_t k = 0;
#define CHECK_FIELD(type, name)                                                                       \
    if (offsets[k] != (int64_t)offsetof(SceneDesc, name) ||                                           \
        sizes[k] != (int64_t)sizeof(((const SceneDesc *)0)->name))                                    \
        return fail("SceneDesc." #name " is laid out differently");                                   \
    k++;
    RT_SCENE_DESC_FIELDS(CHECK_FIELD)
#undef CHECK_FIELD

    /* An empty scene: every pointer at one valid slot, nothing to hit, a background to see. */
    static int64_t zeros_i64[16];
    static double zeros_f64[64];
    static int32_t zeros_i32[16];
    static uint8_t zeros_u8[16];
    static int8_t zeros_i8[16];
    static const double *no_images[1];
    SceneDesc desc;
    memset(&desc, 0, sizeof desc);
#define POINT_AT_ZEROS(type, name) _Generic((desc.name),                                                    \
        const int64_t *: (void)(*(const int64_t **)&desc.name = zeros_i64),                            \
        const double *: (void)(*(const double **)&desc.name = zeros_f64),                              \
        const int32_t *: (void)(*(const int32_t **)&desc.name = zeros_i32),                            \
        const uint8_t *: (void)(*(const uint8_t **)&desc.name = zeros_u8),                             \
        const int8_t *: (void)(*(const int8_t **)&desc.name = zeros_i8),                               \
        const double *const *: (void)(*(const double *const **)&desc.name = no_images),                \
        default: (void)0);
    RT_SCENE_DESC_FIELDS(POINT_AT_ZEROS)
#undef POINT_AT_ZEROS
    desc.background[0] = 0.25;
    desc.background[1] = 0.5;
    desc.background[2] = 0.75;
    desc.max_depth = 1;
    char message[256] = "";
    void *scene = create(&desc, message, sizeof message);
    if (!scene) {
        printf("smoke_core: rt_create refused an empty scene: %s\n", message);
        return 1;
    }
    enum { N = 64 };
    double origins[3 * N], directions[3 * N], colors[3 * N];
    int64_t counts[RAY_KIND_COUNT] = {0};
    for (int i = 0; i < N; i++) {
        origins[3 * i] = origins[3 * i + 1] = origins[3 * i + 2] = 0.0;
        directions[3 * i] = 0.01 * i;
        directions[3 * i + 1] = 1.0;
        directions[3 * i + 2] = -1.0;
    }
    int status = trace(scene, N, origins, directions, colors, counts, 2, 0.0, 0, RAY_BUDGET, NULL);
    destroy(scene);
    if (status != 0)
        return fail("rt_trace failed");
    for (int i = 0; i < 3 * N; i++)
        if (colors[i] != desc.background[i % 3])
            return fail("a ray did not come back with the background colour");
    if (counts[RAY_CAMERA] != N)
        return fail("the camera rays were not counted");
    printf("ok\n");
    return 0;
}
