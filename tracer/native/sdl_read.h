/* Reading big SDL files at I/O speed: a one-pass scanner for the statements that generated scenes use
 * (tracer/sdl/fastread.py is its Python side, tracer/sdl/parser.py the reference it must equal).
 *
 * It either reads the whole text into columns (one row per shape: kind, the top three rows of its matrix,
 * material, parameters, line and column of its keyword; plus lights, cameras, settings and name comments), or it
 * declines: it stops at the first thing outside its subset (a def, a brace, a boolean, a mesh, an unknown
 * word, a word where a number belongs, a statement cut short by the end of the text, a pop without a push,
 * a transform that is not clearly invertible, a value the Python reader would refuse or clamp) and says why
 * and where, and the Python reader reads the text instead.  So it never has to produce a message: every
 * error and warning stays the Python reader's.
 *
 * Bit for bit the same scene as the Python reader:
 * - tokens: runs of bytes that are not white space (scan_is_space, str.split's ASCII set), cut by '!', which
 *   starts a comment up to the next '\n'; lines are counted at '\n' only; columns are 1-based bytes;
 * - text: UTF-8, whose bytes beyond ASCII it reads only inside comments (they are the Python reader's
 *   comments whatever they are: no UTF-8 sequence holds a '\n' byte; see sdl_comment for name comments).
 *   Anywhere else such a byte declines the text: Python's str.split takes some of those characters (U+00A0,
 *   U+3000, ...) for white space.  So every byte before a token on its line is ASCII, and its column in bytes
 *   is its column in characters;
 * - numbers: scan.h's scan_word, NUMBER_RE's grammar with Python float()'s correctly rounded value;
 * - transforms: the operations of transforms.affine_translate, affine_scale, affine_times and rotation(), in
 *   the same order (the core is built with -ffp-contract=off, so no product is fused into a sum), the
 *   "+ 0.0" terms included;
 * - materials: one row per distinct value of the fields (compared with ==, so -0.0 equals 0.0 and the first
 *   value seen is kept), as the Python reader's dict of Materials;
 * - ``! name: text`` comments name the next shape keyword (a later one before it wins); one before a
 *   ``light`` names the light, which is left to the Python reader.
 *
 * The keywords come from the caller (its vocabulary: word, action, argument, count of numbers), so the tables
 * of material keywords and shape kinds (with how many parameters each reads) are the Python reader's own;
 * the actions are the functions below, in the order of contract.h's RT_SDL_ACTIONS, which is generated from
 * tracer/sdl/statements.py (each statement names its action there).
 * Memory is O(text size); there is no recursion. */
#ifndef RT_SDL_READ_H
#define RT_SDL_READ_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* Why a text was declined (0: read). */
enum {
    SDL_READ = 0, SDL_DECLINE_WORD, SDL_DECLINE_BRACE, SDL_DECLINE_NUMBER, SDL_DECLINE_END, SDL_DECLINE_VALUE,
    SDL_DECLINE_POP, SDL_DECLINE_AXIS, SDL_DECLINE_TRANSFORM, SDL_DECLINE_SIZE, SDL_DECLINE_MEMORY,
    SDL_DECLINE_VOCABULARY, SDL_DECLINE_ANGLE, SDL_DECLINE_ASCII, SDL_DECLINE_NAMED_LIGHT
};

static const char sdl_decline_names[] =
    "read word brace number end value pop axis transform size memory vocabulary angle ascii namedLight";

/* A material row: the Material's fields in its order (four colours, six numbers), then the texture, the
 * count of parameters and the parameters (unused ones 0). */
#define SDL_MATERIAL_TEXTURE 18
#define SDL_MATERIAL_COUNT 19
#define SDL_MATERIAL_PARAMETERS 20
#define SDL_MAX_PARAMETERS 10
#define SDL_MATERIAL_WIDTH (SDL_MATERIAL_PARAMETERS + SDL_MAX_PARAMETERS)
#define SDL_MAX_DEPTH 64

/* Settings the text set (bits of SdlResult.settings_set). */
enum { SDL_SET_GLOBAL_AMBIENT = 1, SDL_SET_BACKGROUND = 2, SDL_SET_MIN_REFLECTIVITY = 4,
       SDL_SET_MIN_TRANSPARENCY = 8, SDL_SET_MAX_RECURSION_DEPTH = 16 };

/* What one read gives is contract.h's SdlResult (its fields are contract.py's SDL_RESULT, the table the
 * ctypes mirror fastread.py reads is made from). */

/* Grows *buffer (of *capacity items of size bytes) to hold at least need items; 0 when out of memory. */
static int sdl_reserve(void **buffer, int64_t *capacity, int64_t need, size_t size)
{
    if (need <= *capacity)
        return 1;
    int64_t grown = *capacity < 16 ? 16 : *capacity * 2;
    if (grown < need)
        grown = need;
    void *moved = realloc(*buffer, (size_t)grown * size);
    if (moved == NULL)
        return 0;
    *buffer = moved;
    *capacity = grown;
    return 1;
}

/* Reallocates *buffer to capacity items of size bytes; 0 when out of memory (the old buffer stays). */
static int sdl_resize(void **buffer, int64_t capacity, size_t size)
{
    void *moved = realloc(*buffer, (size_t)capacity * size);
    if (moved == NULL)
        return 0;
    *buffer = moved;
    return 1;
}

/* ---- the vocabulary: word -> (action, argument), an open-addressing table of the caller's words ---- */

#define SDL_VOCABULARY_SLOTS 512

typedef struct {
    const char *word[SDL_VOCABULARY_SLOTS];
    int32_t length[SDL_VOCABULARY_SLOTS];
    int32_t action[SDL_VOCABULARY_SLOTS];  /* -1: empty */
    int32_t argument[SDL_VOCABULARY_SLOTS];
    int32_t count[SDL_VOCABULARY_SLOTS];   /* numbers a shape keyword reads (its parameters) */
} SdlVocabulary;

static uint32_t sdl_hash_word(const char *word, int64_t length)
{
    uint32_t h = 2166136261u;
    for (int64_t i = 0; i < length; i++)
        h = (h ^ (unsigned char)word[i]) * 16777619u;
    return h;
}

/* words: the words, each ended by a NUL; codes: (action, argument, count) for each.  0 if they do not fit. */
static int sdl_vocabulary(SdlVocabulary *v, const char *words, int64_t words_length, const int32_t *codes,
                          int64_t count)
{
    for (int i = 0; i < SDL_VOCABULARY_SLOTS; i++)
        v->action[i] = -1;
    if (count <= 0 || count > SDL_VOCABULARY_SLOTS / 2)
        return 0;
    int64_t at = 0;
    for (int64_t n = 0; n < count; n++) {
        const char *end = at < words_length ? memchr(words + at, '\0', (size_t)(words_length - at)) : NULL;
        const int32_t *code = codes + 3 * n;
        if (end == NULL || code[0] < 0 || code[0] >= RT_SDL_ACTION_COUNT || code[2] < 0 || code[2] > PRIM_PARAMS)
            return 0;
        int64_t length = end - (words + at);
        uint32_t slot = sdl_hash_word(words + at, length) & (SDL_VOCABULARY_SLOTS - 1);
        while (v->action[slot] >= 0)
            slot = (slot + 1) & (SDL_VOCABULARY_SLOTS - 1);
        v->word[slot] = words + at;
        v->length[slot] = (int32_t)length;
        v->action[slot] = code[0];
        v->argument[slot] = code[1];
        v->count[slot] = code[2];
        at += length + 1;
    }
    return 1;
}

/* The slot of a word, or -1 when it is not in the vocabulary. */
static int sdl_lookup(const SdlVocabulary *v, const char *word, int64_t length)
{
    uint32_t slot = sdl_hash_word(word, length) & (SDL_VOCABULARY_SLOTS - 1);
    while (v->action[slot] >= 0) {
        if (v->length[slot] == length && memcmp(v->word[slot], word, (size_t)length) == 0)
            return (int)slot;
        slot = (slot + 1) & (SDL_VOCABULARY_SLOTS - 1);
    }
    return -1;
}

/* ---- tokens ---- */

typedef struct {
    const char *text;
    int64_t length, pos;
    int64_t line, line_start;    /* the current line (1-based) and where it starts */
    int64_t name_start, name_length;  /* the name comment waiting for a shape; length 0: none */
    int64_t non_ascii;           /* where the first byte beyond ASCII outside a plain comment is; -1: none */
} SdlLexer;

static int sdl_is_regex_space(unsigned char c)
{
    /* Python's re \s on ASCII text: the same set as str.split's */
    return scan_is_space(c);
}

/* Skips the comment starting at '!' (text[i]); keeps its name if it is a ``! name: text`` comment with a
 * non-empty name (lexer._NAME_COMMENT_RE).  Returns where its line ends.
 * Bytes beyond ASCII are skipped with the comment, but Python's \s takes some characters beyond ASCII for
 * white space (U+00A0, U+3000, ...): so the name kept is stripped of ASCII white space only (the caller strips
 * the rest, str.strip being the pattern's \s*), and where such a character could decide whether the comment
 * names anything at all (before "name:", or in a name without a byte of ASCII that is not white space, which
 * may be empty to Python), the comment sets lx->non_ascii. */
static int64_t sdl_comment(SdlLexer *lx, int64_t i)
{
    const char *t = lx->text;
    const char *newline = memchr(t + i, '\n', (size_t)(lx->length - i));
    int64_t end = newline != NULL ? newline - t : lx->length;
    int64_t p = i + 1;
    while (p < end && (sdl_is_regex_space((unsigned char)t[p]) || (unsigned char)t[p] >= 0x80))
        p++;
    if (end - p < 5 || memcmp(t + p, "name:", 5) != 0)
        return end;
    for (int64_t j = i + 1; j < p; j++)
        if ((unsigned char)t[j] >= 0x80) {
            if (lx->non_ascii < 0)
                lx->non_ascii = j;
            return end;
        }
    p += 5;
    while (p < end && sdl_is_regex_space((unsigned char)t[p]))
        p++;
    int64_t q = end;
    while (q > p && sdl_is_regex_space((unsigned char)t[q - 1]))
        q--;
    int beyond = 0, visible = 0;  /* bytes beyond ASCII; ASCII bytes that are not white space */
    for (int64_t j = p; j < q; j++) {
        unsigned char c = (unsigned char)t[j];
        beyond |= c >= 0x80;
        visible |= c < 0x80 && !sdl_is_regex_space(c);
    }
    if (beyond && !visible) {
        if (lx->non_ascii < 0)
            lx->non_ascii = p;
        return end;
    }
    if (q > p) {  /* an empty name names nothing (and leaves an earlier one waiting) */
        lx->name_start = p;
        lx->name_length = q - p;
    }
    return end;
}

/* The next token [*start, *end): 1; 0 at the end of the text; -1 at a brace. */
static int sdl_next(SdlLexer *lx, int64_t *start, int64_t *end)
{
    const char *t = lx->text;
    int64_t n = lx->length, i = lx->pos;
    for (;;) {
        while (i < n && scan_is_space((unsigned char)t[i])) {
            if (t[i] == '\n') {
                lx->line++;
                lx->line_start = i + 1;
            }
            i++;
        }
        if (i < n && t[i] == '!') {
            i = sdl_comment(lx, i);
            continue;
        }
        break;
    }
    lx->pos = i;
    if (i == n)
        return 0;
    if (t[i] == '{' || t[i] == '}')
        return -1;
    *start = i;
    while (i < n && !scan_is_space((unsigned char)t[i]) && t[i] != '!' && t[i] != '{' && t[i] != '}') {
        if ((unsigned char)t[i] >= 0x80 && lx->non_ascii < 0)
            lx->non_ascii = i;
        i++;
    }
    *end = i;
    lx->pos = i;
    return 1;
}

/* The next `count` tokens as numbers into out; SDL_READ or why not. */
static int sdl_numbers(SdlLexer *lx, int count, double *out)
{
    for (int k = 0; k < count; k++) {
        int64_t start, end;
        int got = sdl_next(lx, &start, &end);
        if (got == 0)
            return SDL_DECLINE_END;
        if (got < 0)
            return SDL_DECLINE_BRACE;
        if (lx->non_ascii >= 0)
            return SDL_DECLINE_ASCII;
        int ok;
        out[k] = scan_word(lx->text + start, lx->text + end, &ok);
        if (!ok)
            return SDL_DECLINE_NUMBER;
    }
    return SDL_READ;
}

/* ---- transforms: transforms.py's operations, in its order ---- */

static const double sdl_identity_affine[12] = {1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0};

/* m times translation(dx, dy, dz) (transforms.affine_translate) */
static void sdl_translate_by(double *m, double dx, double dy, double dz)
{
    for (int r = 0; r < 3; r++) {
        double *row = m + 4 * r;
        row[3] = row[0] * dx + row[1] * dy + row[2] * dz + row[3];
    }
}

/* m times scaling(sx, sy, sz) (transforms.affine_scale) */
static void sdl_scale_by(double *m, double sx, double sy, double sz)
{
    for (int r = 0; r < 3; r++) {
        double *row = m + 4 * r;
        row[0] = row[0] * sx + 0.0;
        row[1] = row[1] * sy + 0.0;
        row[2] = row[2] * sz + 0.0;
    }
}

/* Called through volatile pointers so that the compiler cannot merge them into one sincos call: the values
 * must be those of libm's cos and sin, which Python's math module calls. */
static double (*volatile sdl_cos)(double) = cos;
static double (*volatile sdl_sin)(double) = sin;

/* The 3x3 of transforms.rotation (row after row); 0 when its axis has no finite non-zero length. */
static int sdl_rotation(double angle, double ux, double uy, double uz, double *out)
{
    double length = sqrt(ux * ux + uy * uy + uz * uz);
    if (length == 0.0 || !(length - length == 0.0))
        return 0;
    double x = ux / length, y = uy / length, z = uz / length;
    static const double degrees_to_radians = 3.14159265358979323846 / 180.0;  /* math.radians */
    double a = angle * degrees_to_radians;
    double c = sdl_cos(a), s = sdl_sin(a);
    if (fmod(angle, 90.0) == 0.0) {  /* Python's round(): half to even, and an int (so never -0.0) */
        c = nearbyint(c) + 0.0;
        s = nearbyint(s) + 0.0;
    }
    double k = 1.0 - c;
    out[0] = c + x * x * k;
    out[1] = x * y * k - z * s;
    out[2] = x * z * k + y * s;
    out[3] = y * x * k + z * s;
    out[4] = c + y * y * k;
    out[5] = y * z * k - x * s;
    out[6] = z * x * k - y * s;
    out[7] = z * y * k + x * s;
    out[8] = c + z * z * k;
    return 1;
}

/* m times the 4x4 whose linear part is r and whose translation is 0 (transforms.affine_times) */
static void sdl_times(double *m, const double *r)
{
    for (int row = 0; row < 3; row++) {
        double *e = m + 4 * row;
        double a = e[0], b = e[1], c = e[2], x = e[3];
        e[0] = a * r[0] + b * r[3] + c * r[6] + 0.0;
        e[1] = a * r[1] + b * r[4] + c * r[7] + 0.0;
        e[2] = a * r[2] + b * r[5] + c * r[8] + 0.0;
        e[3] = a * 0.0 + b * 0.0 + c * 0.0 + x;
    }
}

/* parser._affine_clearly_invertible, where it says yes; 0 also for a few affines it might take (entries
 * beyond 1e300, whose sum could overflow in one summation order and not in another): the Python reader
 * then decides. */
static int sdl_clearly_invertible(const double *m)
{
    double sum = 0.0;
    for (int i = 0; i < 12; i++) {
        if (!(fabs(m[i]) <= 1e300))
            return 0;
        sum += m[i];
    }
    if (!(sum - sum == 0.0))
        return 0;
    double a = m[0], b = m[1], c = m[2], d = m[4], e = m[5], f = m[6], g = m[8], h = m[9], i = m[10];
    double size = fabs(a);
    const double others[8] = {fabs(b), fabs(c), fabs(d), fabs(e), fabs(f), fabs(g), fabs(h), fabs(i)};
    for (int k = 0; k < 8; k++)
        if (others[k] > size)
            size = others[k];
    if (!(1e-80 <= size && size <= 1e80))
        return 0;
    double det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g);
    return fabs(det) >= 1e-9 * size * size * size;
}

/* ---- materials ---- */

static uint64_t sdl_hash_material(const double *row)
{
    uint64_t h = 0;
    for (int i = 0; i < SDL_MATERIAL_WIDTH; i++) {
        double v = row[i] == 0.0 ? 0.0 : row[i];  /* -0.0 and 0.0 are one key */
        uint64_t bits;
        memcpy(&bits, &v, sizeof bits);
        h = (h ^ bits) * 0x9e3779b97f4a7c15ull;
        h ^= h >> 32;
    }
    /* (splitmix64's finaliser: every bit of every field reaches the low bits the table uses) */
    h = (h ^ (h >> 30)) * 0xbf58476d1ce4e5b9ull;
    h = (h ^ (h >> 27)) * 0x94d049bb133111ebull;
    return h ^ (h >> 31);
}

static int sdl_same_material(const double *a, const double *b)
{
    for (int i = 0; i < SDL_MATERIAL_WIDTH; i++)
        if (!(a[i] == b[i]))
            return 0;
    return 1;
}

/* The material table's entries: the top 32 bits of a row's hash (which also choose its slot, so the table
 * grows without the rows) over its id + 1; 0 for an empty slot.  One probe reads one entry, and a row is
 * compared only when its hash's bits match. */
static uint64_t sdl_table_entry(uint64_t hash, int64_t id)
{
    return (hash >> 32 << 32) | (uint64_t)(id + 1);
}

/* The id of the material `row` (added if new), or -1 when out of memory. */
static int32_t sdl_material_id(SdlResult *res, const double *row)
{
    if (2 * (res->materials + 1) > res->table_size) {  /* keep the table at most half full */
        int64_t size = res->table_size ? res->table_size * 2 : 64;
        if (size > ((int64_t)1 << 32))
            return -1;
        uint64_t *table = calloc((size_t)size, sizeof *table), mask = (uint64_t)(size - 1);
        if (table == NULL)
            return -1;
        for (int64_t old = 0; old < res->table_size; old++) {
            uint64_t entry = res->material_table[old];
            if (entry == 0)
                continue;
            uint64_t slot = (entry >> 32) & mask;
            while (table[slot])
                slot = (slot + 1) & mask;
            table[slot] = entry;
        }
        free(res->material_table);
        res->material_table = table;
        res->table_size = size;
    }
    uint64_t hash = sdl_hash_material(row), mask = (uint64_t)(res->table_size - 1), slot = (hash >> 32) & mask;
    for (uint64_t entry; (entry = res->material_table[slot]) != 0; slot = (slot + 1) & mask) {
        int64_t id = (int64_t)(entry & 0xffffffffu) - 1;
        if (entry >> 32 == hash >> 32 && sdl_same_material(res->material_rows + id * SDL_MATERIAL_WIDTH, row))
            return (int32_t)id;
    }
    if (res->materials >= INT32_MAX - 1 ||
        !sdl_reserve((void **)&res->material_rows, &res->material_capacity, res->materials + 1,
                     SDL_MATERIAL_WIDTH * sizeof(double)))
        return -1;
    memcpy(res->material_rows + res->materials * SDL_MATERIAL_WIDTH, row, SDL_MATERIAL_WIDTH * sizeof(double));
    res->material_table[slot] = sdl_table_entry(hash, res->materials);
    return (int32_t)res->materials++;
}

/* ---- the reader ---- */

static int sdl_whole(double value)
{
    return value == floor(value);  /* (values are finite here) */
}

static int sdl_add_shape(SdlResult *res, int16_t kind, const double *affine, int32_t material,
                         const double *parameters, int64_t line, int64_t column)
{
    int64_t n = res->shapes;
    if (n == res->shape_capacity) {  /* the shape columns grow together */
        int64_t capacity = n < 1024 ? 1024 : 2 * n;
        if (!sdl_resize((void **)&res->kinds, capacity, sizeof(int16_t)) ||
            !sdl_resize((void **)&res->affines, capacity, 12 * sizeof(double)) ||
            !sdl_resize((void **)&res->material_ids, capacity, sizeof(int32_t)) ||
            !sdl_resize((void **)&res->parameters, capacity, PRIM_PARAMS * sizeof(double)) ||
            !sdl_resize((void **)&res->lines, capacity, sizeof(int32_t)) ||
            !sdl_resize((void **)&res->columns, capacity, sizeof(int32_t)))
            return 0;
        res->shape_capacity = capacity;
    }
    res->kinds[n] = kind;
    memcpy(res->affines + 12 * n, affine, 12 * sizeof(double));
    res->material_ids[n] = material;
    memcpy(res->parameters + PRIM_PARAMS * n, parameters, PRIM_PARAMS * sizeof(double));
    res->lines[n] = (int32_t)line;
    res->columns[n] = (int32_t)column;
    res->shapes = n + 1;
    return 1;
}

static int sdl_add_row(double **rows, int64_t *count, int64_t *capacity, const double *values, int width)
{
    if (!sdl_reserve((void **)rows, capacity, *count + 1, (size_t)width * sizeof(double)))
        return 0;
    memcpy(*rows + *count * width, values, (size_t)width * sizeof(double));
    ++*count;
    return 1;
}

/* A rotation whose sine and cosine every libm gives alike: a multiple of 90 degrees not too far from 0,
 * whose cosine and sine lie within far less than 1/2 of the integers they are rounded to. */
static int sdl_libm_free(double angle)
{
    return fmod(angle, 90.0) == 0.0 && fabs(angle) <= 1e6;
}

/* What the actions read and change while a text is read. */
typedef struct {
    SdlResult *res;
    SdlLexer *lx;
    const double *defaults;    /* the default material row */
    int shared_libm;           /* see sdl_read */
    double material[SDL_MATERIAL_WIDTH];
    int32_t material_id;       /* of `material`, once a shape needed it; -1: not looked up since it changed */
    int checked;               /* whether the top transform was found clearly invertible */
    int64_t start;             /* where the statement's keyword starts */
} SdlReader;

/* An action's status once it has read past its keyword: where the text is declined is where reading stopped
 * (the first byte beyond ASCII; the keyword itself at the end of the text). */
static int sdl_stopped(SdlReader *r, int status)
{
    if (status == SDL_DECLINE_ASCII)
        r->res->decline_offset = r->lx->non_ascii;
    else if (status != SDL_READ && status != SDL_DECLINE_END)
        r->res->decline_offset = r->lx->pos;
    return status;
}

/* `count` numbers into out, and whether the text goes on (sdl_stopped). */
static int sdl_read_numbers(SdlReader *r, int count, double *out)
{
    return sdl_stopped(r, sdl_numbers(r->lx, count, out));
}

static double *sdl_top(SdlReader *r)
{
    return r->res->stack + 12 * (r->res->depth - 1);
}

/* ---- the actions (tracer/sdl/statements.py names each statement's; a status each) ---- */

static int sdl_light(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    if (r->lx->name_length > 0)  /* a name comment names the light: Light.name, left to the Python reader */
        return SDL_DECLINE_NAMED_LIGHT;
    double v[6];
    int status = sdl_read_numbers(r, 6, v);
    if (status == SDL_READ && !sdl_add_row(&r->res->light_rows, &r->res->lights, &r->res->light_capacity, v, 6))
        return sdl_stopped(r, SDL_DECLINE_MEMORY);
    return status;
}

/* A setting of `count` numbers at `out`, marked set by `bit`. */
static int sdl_setting(SdlReader *r, int count, double *out, int64_t bit)
{
    int status = sdl_read_numbers(r, count, out);
    if (status == SDL_READ)
        r->res->settings_set |= bit;
    return status;
}

static int sdl_global_ambient(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    return sdl_setting(r, 3, r->res->global_ambient, SDL_SET_GLOBAL_AMBIENT);
}

static int sdl_background(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    return sdl_setting(r, 3, r->res->background, SDL_SET_BACKGROUND);
}

static int sdl_min_reflectivity(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    return sdl_setting(r, 1, &r->res->min_reflectivity, SDL_SET_MIN_REFLECTIVITY);
}

static int sdl_min_transparency(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    return sdl_setting(r, 1, &r->res->min_transparency, SDL_SET_MIN_TRANSPARENCY);
}

/* beyond the limit the Python reader warns and clamps; not whole or negative is an error */
static int sdl_max_recursion_depth(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    double v;
    int status = sdl_read_numbers(r, 1, &v);
    if (status != SDL_READ)
        return status;
    if (!sdl_whole(v) || v < 0.0 || v > SDL_MAX_DEPTH)
        return sdl_stopped(r, SDL_DECLINE_VALUE);
    r->res->max_recursion_depth = (int64_t)v;
    r->res->settings_set |= SDL_SET_MAX_RECURSION_DEPTH;
    return SDL_READ;
}

/* checked by the caller, as parser._camera checks it */
static int sdl_camera(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    double v[10];
    int status = sdl_read_numbers(r, 10, v);
    if (status == SDL_READ && !sdl_add_row(&r->res->camera_rows, &r->res->cameras, &r->res->camera_capacity, v, 10))
        return sdl_stopped(r, SDL_DECLINE_MEMORY);
    return status;
}

/* `width` numbers into the material's slot `argument` (a field of its row before the texture) */
static int sdl_material_field(SdlReader *r, int32_t argument, int width)
{
    if (argument < 0 || argument + width > SDL_MATERIAL_TEXTURE)
        return SDL_DECLINE_VOCABULARY;
    int status = sdl_read_numbers(r, width, r->material + argument);
    if (status == SDL_READ)
        r->material_id = -1;
    return status;
}

static int sdl_color_material(SdlReader *r, int32_t argument, int32_t count)
{
    (void)count;
    return sdl_material_field(r, argument, 3);
}

static int sdl_float_material(SdlReader *r, int32_t argument, int32_t count)
{
    (void)count;
    return sdl_material_field(r, argument, 1);
}

static int sdl_texture(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    double v;
    int status = sdl_read_numbers(r, 1, &v);
    if (status != SDL_READ)
        return status;
    if (!sdl_whole(v) || v < -2147483648.0 || v > 2147483647.0)
        return sdl_stopped(r, SDL_DECLINE_VALUE);
    r->material[SDL_MATERIAL_TEXTURE] = v + 0.0;  /* int(-0.0) is 0 */
    r->material_id = -1;
    return SDL_READ;
}

static int sdl_parameters(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    double v;
    int status = sdl_read_numbers(r, 1, &v);
    if (status != SDL_READ)
        return status;
    if (!sdl_whole(v) || v < 0.0 || v > SDL_MAX_PARAMETERS)
        return sdl_stopped(r, SDL_DECLINE_VALUE);
    double values[SDL_MAX_PARAMETERS] = {0.0};
    if ((status = sdl_read_numbers(r, (int)v, values)) == SDL_READ) {
        r->material[SDL_MATERIAL_COUNT] = (int)v;
        memcpy(r->material + SDL_MATERIAL_PARAMETERS, values, sizeof values);
        r->material_id = -1;
    }
    return status;
}

static int sdl_default_materials(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    memcpy(r->material, r->defaults, sizeof r->material);
    r->material_id = -1;
    return SDL_READ;
}

static int sdl_translate(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    double v[3];
    int status = sdl_read_numbers(r, 3, v);
    if (status == SDL_READ) {
        sdl_translate_by(sdl_top(r), v[0], v[1], v[2]);
        r->checked = 0;
    }
    return status;
}

static int sdl_scale(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    double v[3];
    int status = sdl_read_numbers(r, 3, v);
    if (status == SDL_READ) {
        sdl_scale_by(sdl_top(r), v[0], v[1], v[2]);
        r->checked = 0;
    }
    return status;
}

/* With shared_libm 0, angles other than sdl_libm_free ones are declined. */
static int sdl_rotate(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    double v[4], m[9];
    int status = sdl_read_numbers(r, 4, v);
    if (status != SDL_READ)
        return status;
    if (!r->shared_libm && !sdl_libm_free(v[0]))
        return sdl_stopped(r, SDL_DECLINE_ANGLE);
    if (!sdl_rotation(v[0], v[1], v[2], v[3], m))
        return sdl_stopped(r, SDL_DECLINE_AXIS);
    sdl_times(sdl_top(r), m);
    r->checked = 0;
    return SDL_READ;
}

static int sdl_push(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    SdlResult *res = r->res;
    if (!sdl_reserve((void **)&res->stack, &res->stack_capacity, res->depth + 1, 12 * sizeof(double)))
        return SDL_DECLINE_MEMORY;
    memcpy(res->stack + 12 * res->depth, res->stack + 12 * (res->depth - 1), 12 * sizeof(double));
    res->depth++;
    return SDL_READ;
}

static int sdl_pop(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    if (r->res->depth == 1)
        return SDL_DECLINE_POP;
    r->res->depth--;
    r->checked = 0;
    return SDL_READ;
}

static int sdl_identity(SdlReader *r, int32_t argument, int32_t count)
{
    (void)argument, (void)count;
    memcpy(sdl_top(r), sdl_identity_affine, sizeof sdl_identity_affine);
    r->checked = 0;
    return SDL_READ;
}

/* A shape of kind code `argument` reading `count` parameters: a row of the shape columns, with the name a
 * comment gave it. */
static int sdl_shape(SdlReader *r, int32_t argument, int32_t count)
{
    SdlResult *res = r->res;
    SdlLexer *lx = r->lx;
    int64_t line = lx->line, column = r->start - lx->line_start + 1;
    int64_t name_start = lx->name_start, name_length = lx->name_length;
    lx->name_length = 0;  /* a name comment names the first shape keyword after it */
    double parameters[PRIM_PARAMS] = {0.0};
    int status = sdl_read_numbers(r, count, parameters);
    if (status != SDL_READ)
        return status;
    double *top = sdl_top(r);
    if (!r->checked && !sdl_clearly_invertible(top))
        return SDL_DECLINE_TRANSFORM;
    r->checked = 1;
    if (line > INT32_MAX || column > INT32_MAX || argument < 0 || argument > INT16_MAX)
        return SDL_DECLINE_SIZE;
    if (r->material_id < 0 && (r->material_id = sdl_material_id(res, r->material)) < 0)
        return SDL_DECLINE_MEMORY;
    if (name_length > 0) {
        int64_t row[3] = {res->shapes, name_start, name_length};
        if (!sdl_reserve((void **)&res->name_rows, &res->name_capacity, res->names + 1, sizeof row))
            return SDL_DECLINE_MEMORY;
        memcpy(res->name_rows + 3 * res->names++, row, sizeof row);
    }
    if (!sdl_add_shape(res, (int16_t)argument, top, r->material_id, parameters, line, column))
        return SDL_DECLINE_MEMORY;
    return SDL_READ;
}

/* The action of code `action` (tracer/sdl/statements.py's ACTIONS, contract.h's RT_SDL_ACTIONS). */
static inline int sdl_act(SdlReader *r, int32_t action, int32_t argument, int32_t count)
{
    switch (action) {
#define SDL_ACTION_CASE(code, function) case code: return function(r, argument, count);
    RT_SDL_ACTIONS(SDL_ACTION_CASE)
#undef SDL_ACTION_CASE
    }
    return SDL_DECLINE_VOCABULARY;
}

/* Reads text into res (zeroed by the caller); returns SDL_READ or why it declined, with res->decline_offset
 * where: the keyword that cannot be read, or where its statement stopped being readable.  With shared_libm 0
 * (the caller's math library may not be this library's: Python's cos and sin could differ in the last bit),
 * rotations by angles other than sdl_libm_free ones are declined. */
static int sdl_read(SdlResult *res, SdlLexer *lx, const SdlVocabulary *vocabulary, const double *defaults,
                    int shared_libm)
{
    SdlReader r = {res, lx, defaults, shared_libm, {0.0}, -1, 0, 0};
    memcpy(r.material, defaults, sizeof r.material);
    if (!sdl_reserve((void **)&res->stack, &res->stack_capacity, 1, 12 * sizeof(double)))
        return SDL_DECLINE_MEMORY;
    memcpy(res->stack, sdl_identity_affine, sizeof sdl_identity_affine);
    res->depth = 1;
    for (;;) {
        int64_t start, end;
        int got = sdl_next(lx, &start, &end);
        if (lx->non_ascii >= 0) {
            res->decline_offset = lx->non_ascii;
            return SDL_DECLINE_ASCII;
        }
        if (got == 0)
            return SDL_READ;
        res->decline_offset = lx->pos;
        if (got < 0)
            return SDL_DECLINE_BRACE;
        res->decline_offset = r.start = start;
        int slot = sdl_lookup(vocabulary, lx->text + start, end - start);
        if (slot < 0)
            return SDL_DECLINE_WORD;
        int status = sdl_act(&r, vocabulary->action[slot], vocabulary->argument[slot], vocabulary->count[slot]);
        if (status != SDL_READ)
            return status;
    }
}

/* Frees a result of rt_sdl_read (NULL is fine). */
void rt_sdl_free(SdlResult *res)
{
    if (res == NULL)
        return;
    free(res->kinds);
    free(res->affines);
    free(res->material_ids);
    free(res->parameters);
    free(res->lines);
    free(res->columns);
    free(res->material_rows);
    free(res->light_rows);
    free(res->camera_rows);
    free(res->name_rows);
    free(res->material_table);
    free(res->stack);
    free(res);
}

/* Reads text[0, length).  words/codes/count: the vocabulary (see sdl_vocabulary); defaults: the default
 * material row; shared_libm: whether the caller's cos and sin are this library's (see sdl_read).
 * Returns a result for rt_sdl_free whose status says whether it was read (NULL only when out of memory); a
 * declined result keeps nothing but its reason and place. */
SdlResult *rt_sdl_read(const char *text, int64_t length, const char *words, int64_t words_length,
                       const int32_t *codes, int64_t count, const double *defaults, int64_t shared_libm)
{
    SdlResult *res = calloc(1, sizeof *res);
    if (res == NULL)
        return NULL;
    SdlVocabulary *vocabulary = malloc(sizeof *vocabulary);
    if (vocabulary == NULL) {
        free(res);
        return NULL;
    }
    if (!sdl_vocabulary(vocabulary, words, words_length, codes, count) || length < 0) {
        res->status = SDL_DECLINE_VOCABULARY;
    } else {
        SdlLexer lx = {text, length, 0, 1, 0, 0, 0, -1};
        res->status = sdl_read(res, &lx, vocabulary, defaults, shared_libm != 0);
    }
    free(vocabulary);
    if (res->status != SDL_READ) {  /* keep nothing but the reason */
        int64_t status = res->status, offset = res->decline_offset;
        rt_sdl_free(res);
        res = calloc(1, sizeof *res);
        if (res == NULL)
            return NULL;
        res->status = status;
        res->decline_offset = offset;
    }
    return res;
}

const char *rt_sdl_decline_names(void)
{
    return sdl_decline_names;
}

int64_t rt_sdl_material_width(void)
{
    return SDL_MATERIAL_WIDTH;
}

#endif
