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

#endif
