/* Reading files of white-space separated decimal numbers at I/O speed (the .3vn reader's fast path,
 * tracer/meshio.py).
 *
 * A word is accepted only if it is what tracer.sdl.lexer.NUMBER_RE accepts and gives a finite double:
 * [+-]? (digits [. digits?] | . digits) ([eE] [+-]? digits)?.  White space is Python's str.split() set in
 * ASCII.  Anything else (another byte, a malformed word, an overflow) stops the scan with the word's
 * offset: the word-by-word Python reader then re-reads the file and names the problem, so this code
 * never has to produce a message.
 *
 * Values are those of Python's float(): the correctly rounded double.  Words with at most 15 significant
 * digits and a decimal exponent within 10^±22 take Clinger's fast path (the digits and the power of ten
 * are exact doubles, so one multiplication or division rounds correctly); the others go to strtod. */
#ifndef RT_SCAN_H
#define RT_SCAN_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static inline int scan_is_space(unsigned char c)
{
    return c == ' ' || (c >= '\t' && c <= '\r') || (c >= 0x1c && c <= 0x1f);
}

static const double scan_powers[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                       1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

/* The value of the word [start, end), or 0 with *ok = 0 when it is not a finite decimal number. */
static double scan_word(const char *start, const char *end, int *ok)
{
    const char *p = start;
    int negative = 0;
    if (*p == '+' || *p == '-')
        negative = *p++ == '-';
    uint64_t digits = 0;
    int significant = 0, integer_digits = 0, fraction_digits = 0;
    int64_t scale = 0;  /* the value is digits * 10^scale */
    for (; p < end && *p >= '0' && *p <= '9'; p++, integer_digits++) {
        if (significant == 0 && *p == '0')
            continue;
        if (significant < 19)
            digits = digits * 10 + (uint64_t)(*p - '0');
        else
            scale++;
        significant++;
    }
    if (p < end && *p == '.') {
        for (p++; p < end && *p >= '0' && *p <= '9'; p++, fraction_digits++) {
            if (significant == 0 && *p == '0') {
                scale--;
                continue;
            }
            if (significant < 19) {
                digits = digits * 10 + (uint64_t)(*p - '0');
                scale--;
            }
            significant++;
        }
    }
    *ok = 0;
    if (integer_digits == 0 && fraction_digits == 0)
        return 0.0;
    if (p < end && (*p == 'e' || *p == 'E')) {
        p++;
        int exponent_negative = 0;
        if (p < end && (*p == '+' || *p == '-'))
            exponent_negative = *p++ == '-';
        if (p == end)
            return 0.0;
        int64_t exponent = 0;
        for (; p < end && *p >= '0' && *p <= '9'; p++)
            if (exponent < 100000)
                exponent = exponent * 10 + (*p - '0');
        scale += exponent_negative ? -exponent : exponent;
    }
    if (p != end)
        return 0.0;
    double value;
    if (significant == 0) {
        value = 0.0;
    } else if (significant <= 15 && scale >= -22 && scale <= 22) {
        value = (double)digits;
        value = scale < 0 ? value / scan_powers[-scale] : value * scan_powers[scale];
    } else {
        char buffer[512];
        const char *unsigned_start = start + (*start == '+' || *start == '-');
        size_t length = (size_t)(end - unsigned_start);
        if (length >= sizeof buffer)
            return 0.0;
        memcpy(buffer, unsigned_start, length);
        buffer[length] = '\0';
        char *stop;
        value = strtod(buffer, &stop);
        if (stop != buffer + length)  /* (a locale with another decimal point: let Python read it) */
            return 0.0;
    }
    if (!(value - value == 0.0))  /* inf or NaN */
        return 0.0;
    *ok = 1;
    return negative ? -value : value;
}

/* Scan text[0, length): with out == NULL, count the words (-1 at a byte that is neither ASCII white space
 * nor printable ASCII); else store each word's value in out[0, capacity) and return how many there
 * were, or -1 with *bad = the offset of the first word that is not a number (or of a byte outside
 * ASCII, or of the word that would not fit). */
int64_t rt_scan_numbers(const char *text, int64_t length, double *out, int64_t capacity, int64_t *bad)
{
    int64_t count = 0, i = 0;
    *bad = -1;
    while (i < length) {
        while (i < length && scan_is_space((unsigned char)text[i]))
            i++;
        if (i == length)
            break;
        int64_t start = i;
        while (i < length && !scan_is_space((unsigned char)text[i])) {
            unsigned char c = (unsigned char)text[i];
            if (c < 0x20 || c >= 0x7f) {
                *bad = i;
                return -1;
            }
            i++;
        }
        if (out) {
            int ok;
            if (count >= capacity) {
                *bad = start;
                return -1;
            }
            out[count] = scan_word(text + start, text + i, &ok);
            if (!ok) {
                *bad = start;
                return -1;
            }
        }
        count++;
    }
    return count;
}

/* A .3vn file read straight into its arrays (tracer/meshio.py's fast path): no array of all its numbers.
 *
 * A cursor over the words of a text: scan_next gives the next word's value (1), the end (0), or -1 at a word
 * that is not a number (or a byte that is not printable ASCII). */
typedef struct {
    const char *text;
    int64_t length, pos;
} ScanCursor;

static int scan_next(ScanCursor *c, double *value)
{
    const char *text = c->text;
    int64_t i = c->pos, length = c->length;
    while (i < length && scan_is_space((unsigned char)text[i]))
        i++;
    if (i == length) {
        c->pos = i;
        return 0;
    }
    int64_t start = i;
    while (i < length && !scan_is_space((unsigned char)text[i])) {
        unsigned char ch = (unsigned char)text[i];
        if (ch < 0x20 || ch >= 0x7f)
            return -1;
        i++;
    }
    c->pos = i;
    int ok;
    *value = scan_word(text + start, text + i, &ok);
    return ok ? 1 : -1;
}

/* The next word as a whole number in [low, high] ("3.0" is one); 0 if it is not that. */
static int scan_whole(ScanCursor *c, double low, double high, int64_t *out)
{
    double v;
    if (scan_next(c, &v) != 1 || v != floor(v) || v < low || v > high)
        return 0;
    *out = (int64_t)v;
    return 1;
}

#define SCAN_BIG 2147483647.0 /* meshio._BIG: larger counts are certainly corrupt */

/* counts: vertices, normals, faces, corners (the sum of the faces' sizes).  With vertices == NULL, reads
 * the three counts at the start and finds the corners from the number of words after them (which bounds
 * every array by the file's size); else reads every number into the arrays (vertices and normals 3 each;
 * per face its size, then its vertex and normal indices) and checks that the file is exactly that: whole
 * numbers where indices and sizes go, sizes of at least 3, indices in range, nothing after the last face.
 * Returns 0, or -1 for anything else: the word-by-word reader then says what is wrong and where. */
int64_t rt_scan_3vn(const char *text, int64_t length, int64_t *counts, double *vertices, double *normals,
                    int64_t *sizes, int32_t *vertex_index, int32_t *normal_index)
{
    ScanCursor c = {text, length, 0};
    int64_t head[3];
    for (int k = 0; k < 3; k++)
        if (!scan_whole(&c, 0.0, SCAN_BIG, &head[k]))
            return -1;
    int64_t n_vertices = head[0], n_normals = head[1], n_faces = head[2];
    if (!vertices) {
        int64_t bad;
        int64_t words = rt_scan_numbers(text + c.pos, length - c.pos, NULL, 0, &bad);
        int64_t rest = words - 3 * (n_vertices + n_normals) - n_faces;
        if (words < 0 || rest < 6 * n_faces || rest % 2)
            return -1;
        counts[0] = n_vertices, counts[1] = n_normals, counts[2] = n_faces, counts[3] = rest / 2;
        return 0;
    }
    if (n_vertices != counts[0] || n_normals != counts[1] || n_faces != counts[2])
        return -1;
    for (int64_t i = 0; i < 3 * n_vertices; i++)
        if (scan_next(&c, &vertices[i]) != 1)
            return -1;
    for (int64_t i = 0; i < 3 * n_normals; i++)
        if (scan_next(&c, &normals[i]) != 1)
            return -1;
    int64_t used = 0, corners = counts[3];
    for (int64_t f = 0; f < n_faces; f++) {
        int64_t n, index;
        if (!scan_whole(&c, 3.0, SCAN_BIG, &n) || n > corners - used)
            return -1;
        sizes[f] = n;
        for (int64_t k = 0; k < n; k++) {
            if (!scan_whole(&c, 0.0, (double)(n_vertices - 1), &index))
                return -1;
            vertex_index[used + k] = (int32_t)index;
        }
        for (int64_t k = 0; k < n; k++) {
            if (!scan_whole(&c, 0.0, (double)(n_normals - 1), &index))
                return -1;
            normal_index[used + k] = (int32_t)index;
        }
        used += n;
    }
    double extra;
    return used == corners && scan_next(&c, &extra) == 0 ? 0 : -1;
}

#endif
