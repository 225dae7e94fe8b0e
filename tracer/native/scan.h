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

#define SCAN_BIG 2147483647.0 /* meshio._BIG: larger counts are certainly corrupt */

/* The reader's state between pieces of a file (an int64 array on the Python side, so that a file is read a
 * few megabytes at a time): SCAN3_WORD words read, SCAN3_V/N/F the counts at the start, SCAN3_CORNERS the
 * corners (the sum of the faces' sizes), SCAN3_FACE the face being read, SCAN3_AT the position in its record
 * (0: its size, 1..n: vertex indices, n+1..2n: normal indices), SCAN3_SIZE its size, SCAN3_USED the corners
 * of the faces before it. */
enum { SCAN3_WORD, SCAN3_V, SCAN3_N, SCAN3_F, SCAN3_CORNERS, SCAN3_FACE, SCAN3_AT, SCAN3_SIZE, SCAN3_USED,
       SCAN3_STATE };

int64_t rt_scan3_state_size(void) { return SCAN3_STATE; }

/* One piece of a .3vn file (whole words: it ends at white space or at the end of the file), read straight
 * into the mesh's arrays (tracer/meshio.py's fast path; no array of all its numbers).  With vertices ==
 * NULL (the first pass) only the three counts are read and the words counted; the second pass, with the
 * arrays sized from the first, reads every number and checks that the file is exactly a .3vn: whole numbers
 * where sizes and indices go, sizes of at least 3, indices in range (normal indices into an empty list are
 * not).  Returns 0, or -1 at anything else: the word-by-word reader then says what is wrong and where. */
int64_t rt_scan_3vn(int64_t *state, const char *text, int64_t length, double *vertices, double *normals,
                    int64_t *sizes, int32_t *vertex_index, int32_t *normal_index)
{
    ScanCursor c = {text, length, 0};
    int64_t *st = state;
    for (;;) {
        int64_t word = st[SCAN3_WORD];
        if (word >= 3 && !vertices) {  /* first pass, after the counts: count the rest */
            int64_t bad, words = rt_scan_numbers(text + c.pos, length - c.pos, NULL, 0, &bad);
            if (words < 0)
                return -1;
            st[SCAN3_WORD] += words;
            return 0;
        }
        double value;
        int got = scan_next(&c, &value);
        if (got <= 0)
            return got;  /* 0: the end of this piece */
        st[SCAN3_WORD]++;
        if (word < 3) {  /* a count */
            if (value != floor(value) || value < 0.0 || value > SCAN_BIG ||
                (vertices && (int64_t)value != st[SCAN3_V + word]))
                return -1;
            st[SCAN3_V + word] = (int64_t)value;
            continue;
        }
        int64_t nv = 3 * st[SCAN3_V], nn = 3 * st[SCAN3_N], i = word - 3;
        if (i < nv) {
            vertices[i] = value;
            continue;
        }
        if (i < nv + nn) {
            normals[i - nv] = value;
            continue;
        }
        int64_t at = st[SCAN3_AT], used = st[SCAN3_USED];
        if (value != floor(value) || st[SCAN3_FACE] >= st[SCAN3_F])
            return -1;
        if (at == 0) {
            if (value < 3.0 || value > SCAN_BIG || (int64_t)value > st[SCAN3_CORNERS] - used)
                return -1;
            sizes[st[SCAN3_FACE]] = st[SCAN3_SIZE] = (int64_t)value;
        } else if (at <= st[SCAN3_SIZE]) {
            if (value < 0.0 || value >= (double)st[SCAN3_V])
                return -1;
            vertex_index[used + at - 1] = (int32_t)value;
        } else {
            if (value < 0.0 || value >= (double)st[SCAN3_N])
                return -1;
            normal_index[used + at - st[SCAN3_SIZE] - 1] = (int32_t)value;
        }
        if (at == 2 * st[SCAN3_SIZE]) {  /* the face's last normal index */
            st[SCAN3_USED] += st[SCAN3_SIZE];
            st[SCAN3_FACE]++;
            st[SCAN3_AT] = 0;
        } else {
            st[SCAN3_AT] = at + 1;
        }
    }
}

/* After the first pass: the corners the faces must have (from the number of words, which bounds every
 * array by the file's size), or -1 if the words cannot be such a file.  After the second: 0 if every face
 * was read whole and nothing followed, else -1. */
int64_t rt_scan_3vn_end(int64_t *state, int filled)
{
    int64_t *st = state;
    if (st[SCAN3_WORD] < 3)
        return -1;
    if (filled)
        return st[SCAN3_FACE] == st[SCAN3_F] && st[SCAN3_AT] == 0 && st[SCAN3_USED] == st[SCAN3_CORNERS] ? 0 : -1;
    int64_t rest = st[SCAN3_WORD] - 3 - 3 * (st[SCAN3_V] + st[SCAN3_N]) - st[SCAN3_F];
    if (rest < 6 * st[SCAN3_F] || rest % 2)
        return -1;
    return st[SCAN3_CORNERS] = rest / 2;
}
#endif
