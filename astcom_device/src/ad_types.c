/* ASTCom types (§2.3): parse the type text, coerce wire values into C storage and back. */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "ad_internal.h"

static const char *const SCALARS[] = {"bool", "i8", "i16", "i32", "i64", "u8", "u16", "u32",
                                      "u64", "f32", "f64", "str", "bytes"};

uint32_t ad_scalar_size(uint8_t base)
{
    return base <= 10 ? AD_DTYPE_SIZE[base] : 0;
}

static int scalar_code(const char *p, size_t n)
{
    for (int i = 0; i < 13; i++)
        if (strlen(SCALARS[i]) == n && !memcmp(SCALARS[i], p, n)) return i;
    return -1;
}

void ad_struct_begin(ad_struct_it *it, const char *text)
{
    it->p = text + 1;
    it->end = text + strlen(text) - 1;
    it->offset = 0;
    it->align = 1;
}

/* 0: a field; 1: no more; -1: malformed */
int ad_struct_next(ad_struct_it *it, const char **name, uint32_t *name_len, uint8_t *base)
{
    if (it->p >= it->end) return 1;
    const char *colon = memchr(it->p, ':', (size_t)(it->end - it->p));
    if (!colon || colon == it->p) return -1;
    const char *comma = memchr(colon, ',', (size_t)(it->end - colon));
    const char *stop = comma ? comma : it->end;
    int code = scalar_code(colon + 1, (size_t)(stop - colon - 1));
    if (code < 0 || code > 10) return -1;
    uint32_t size = ad_scalar_size((uint8_t)code);
    /* the offset of this field: after the previous one, aligned */
    uint32_t off = it->offset;
    *name = it->p;
    *name_len = (uint32_t)(colon - it->p);
    *base = (uint8_t)code;
    off = (off + size - 1) / size * size;
    it->offset = off;
    if (size > it->align) it->align = size;
    it->p = comma ? comma + 1 : it->end;
    return 0; /* callers set `offset` to the end of the previous field before each call */
}

int ad_parse_type(const char *text, size_t len, ad_type *out)
{
    memset(out, 0, sizeof *out);
    if (len && text[0] == '{') {
        /* struct offsets: ad_struct_next returns each field's offset; sizes add up here */
        ad_struct_it it;
        const char *name;
        uint32_t nl, size = 0, align = 1, n = 0;
        uint8_t base;
        if (len < 2 || text[len - 1] != '}') return -1;
        it.p = text + 1;
        it.end = text + len - 1;
        it.offset = 0;
        it.align = 1;
        while (1) {
            it.offset = size;
            int r = ad_struct_next(&it, &name, &nl, &base);
            if (r > 0) break;
            if (r < 0) return -1;
            size = it.offset + ad_scalar_size(base);
            align = it.align;
            n++;
        }
        if (!n) return -1;
        out->base = AD_T_STRUCT;
        out->count = 1;
        out->c_size = (size + align - 1) / align * align;
        return 0;
    }
    const char *br = memchr(text, '[', len);
    size_t blen = br ? (size_t)(br - text) : len;
    int code = scalar_code(text, blen);
    if (code < 0) {
        if (blen == 4 && !memcmp(text, "none", 4) && !br) { out->base = AD_T_NONE; return 0; }
        return -1;
    }
    out->base = (uint8_t)code;
    out->count = 1;
    if (!br) {
        out->c_size = code <= 10 ? ad_scalar_size((uint8_t)code) : 0;
        return 0;
    }
    if (code > 10 || text[len - 1] != ']') return -1;
    const char *p = br + 1, *end = text + len - 1;
    if (p == end) { out->ndim = AD_VARLEN; out->count = 0; return 0; }
    while (p < end) {
        uint64_t d = 0;
        const char *q = p;
        while (q < end && *q >= '0' && *q <= '9') { d = d * 10 + (uint64_t)(*q - '0'); q++; if (d > 0xffffffu) return -1; }
        if (q == p || d == 0 || out->ndim == 4) return -1;
        out->shape[out->ndim++] = (uint32_t)d;
        out->count *= (uint32_t)d;
        if (out->count > 0xffffffu) return -1;
        if (q < end && *q != ',') return -1;
        p = q < end ? q + 1 : q;
    }
    out->c_size = out->count * ad_scalar_size((uint8_t)code);
    return 0;
}

/* ---- loading and storing numbers ----------------------------------------------------- */
double ad_load_f64(uint8_t base, const void *p)
{
    switch (base) {
    case 0: { uint8_t v; memcpy(&v, p, 1); return v; }
    case 1: { int8_t v; memcpy(&v, p, 1); return v; }
    case 2: { int16_t v; memcpy(&v, p, 2); return v; }
    case 3: { int32_t v; memcpy(&v, p, 4); return v; }
    case 4: { int64_t v; memcpy(&v, p, 8); return (double)v; }
    case 5: { uint8_t v; memcpy(&v, p, 1); return v; }
    case 6: { uint16_t v; memcpy(&v, p, 2); return v; }
    case 7: { uint32_t v; memcpy(&v, p, 4); return v; }
    case 8: { uint64_t v; memcpy(&v, p, 8); return (double)v; }
    case 9: { float v; memcpy(&v, p, 4); return v; }
    default: { double v; memcpy(&v, p, 8); return v; }
    }
}

int64_t ad_load_i64(uint8_t base, const void *p)
{
    switch (base) {
    case 4: { int64_t v; memcpy(&v, p, 8); return v; }
    case 8: { uint64_t v; memcpy(&v, p, 8); return (int64_t)v; }
    case 9: case 10: return (int64_t)ad_load_f64(base, p);
    default: return (int64_t)ad_load_f64(base, p);
    }
}

/* A number read off the wire, kept exactly. */
typedef struct num {
    uint8_t kind;   /* 0 uint, 1 negative int, 2 float, 3 bool */
    uint64_t u;
    int64_t i;
    double f;
} num;

static const char *vt_name(uint8_t t)
{
    static const char *const N[] = {"NoneType", "bool", "int", "int", "float", "str", "bytes",
                                    "list", "dict", "ExtType"};
    return t <= AD_VT_EXT ? N[t] : "?";
}

static int fmt_num(const num *n, char *out, size_t len)
{
    if (n->kind == 0) return ad_snprintf(out, len, "%llu", (unsigned long long)n->u);
    if (n->kind == 1) return ad_snprintf(out, len, "%lld", (long long)n->i);
    return ad_snprintf(out, len, "%.17g", n->f);
}

static const int64_t IMIN[11] = {0, INT8_MIN, INT16_MIN, INT32_MIN, INT64_MIN, 0, 0, 0, 0, 0, 0};
static const uint64_t UMAX[11] = {1, INT8_MAX, INT16_MAX, INT32_MAX, INT64_MAX, UINT8_MAX,
                                  UINT16_MAX, UINT32_MAX, UINT64_MAX, 0, 0};

/* Store number `n` as `base` into dst; 0 or 422 (why). `elem` names arrays' elements. */
static int store_num(const num *n, uint8_t base, void *dst, const char *where, int elem,
                     char *why, size_t why_len)
{
    static const char *const NAMES[] = {"bool", "i8", "i16", "i32", "i64", "u8", "u16", "u32",
                                        "u64", "f32", "f64"};
    char shown[40];
    fmt_num(n, shown, sizeof shown);
    if (base == 0) {
        int ok = n->kind == 3 || (n->kind == 0 && n->u <= 1)
                 || (elem && n->kind == 2 && (n->f == 0.0 || n->f == 1.0));
        if (!ok) {
            ad_snprintf(why, why_len, elem ? "%s: expected bool elements (true/false or 0/1)"
                                        : "%s: expected bool (true/false), got %s", where, shown);
            return 422;
        }
        uint8_t b = n->kind == 3 ? (uint8_t)n->u : n->kind == 0 ? (uint8_t)n->u : (uint8_t)n->f;
        memcpy(dst, &b, 1);
        return 0;
    }
    if (n->kind == 3) {
        ad_snprintf(why, why_len, elem ? "%s: expected %s elements, got a bool element"
                                    : "%s: expected %s, got bool %s", where, NAMES[base],
                 n->u ? "True" : "False");
        return 422;
    }
    if (base >= 9) {
        double d = n->kind == 0 ? (double)n->u : n->kind == 1 ? (double)n->i : n->f;
        if (base == 9) {
            if (isfinite(d) && fabs(d) > FLT_MAX) {
                ad_snprintf(why, why_len, elem ? "%s: elements out of range for f32"
                                            : "%s: %s out of range for f32", where, shown);
                return 422;
            }
            float f = (float)d;
            memcpy(dst, &f, 4);
        } else {
            memcpy(dst, &d, 8);
        }
        return 0;
    }
    /* integers */
    int neg = 0;
    uint64_t mag = 0;
    if (n->kind == 2) {
        if (!isfinite(n->f) || n->f != floor(n->f)) {
            ad_snprintf(why, why_len, elem ? "%s: expected integer elements for %s, got fractions"
                                        : "%s: expected an integer for %s, got %s", where,
                     NAMES[base], shown);
            return 422;
        }
        if (n->f < 0) { neg = 1; mag = n->f < -9.3e18 ? UINT64_MAX : (uint64_t)(-n->f); }
        else mag = n->f >= 1.8446744073709552e19 ? UINT64_MAX : (uint64_t)n->f;
    } else if (n->kind == 1) {
        neg = 1;
        mag = (uint64_t)(-(n->i + 1)) + 1;
    } else {
        mag = n->u;
    }
    int bad = neg ? (IMIN[base] == 0 || mag > (uint64_t)(-(IMIN[base] + 1)) + 1) : mag > UMAX[base];
    if (bad) {
        char lo[24], hi[24];
        ad_snprintf(lo, sizeof lo, "%lld", (long long)IMIN[base]);
        ad_snprintf(hi, sizeof hi, "%llu", (unsigned long long)UMAX[base]);
        ad_snprintf(why, why_len, elem ? "%s: elements out of range for %s (%s..%s)"
                                    : "%s: %s out of range for %s (%s..%s)", where,
                 elem ? NAMES[base] : shown, elem ? lo : NAMES[base], elem ? hi : lo,
                 elem ? "" : hi);
        if (elem) ad_snprintf(why, why_len, "%s: elements out of range for %s (%s..%s)", where,
                           NAMES[base], lo, hi);
        return 422;
    }
    uint64_t bits = neg ? (uint64_t)0 - mag : mag;
    switch (AD_DTYPE_SIZE[base]) {
    case 1: { uint8_t v = (uint8_t)bits; memcpy(dst, &v, 1); break; }
    case 2: { uint16_t v = (uint16_t)bits; memcpy(dst, &v, 2); break; }
    case 4: { uint32_t v = (uint32_t)bits; memcpy(dst, &v, 4); break; }
    default: memcpy(dst, &bits, 8); break;
    }
    return 0;
}

static int to_num(const ad_val *v, num *n)
{
    memset(n, 0, sizeof *n);
    switch (v->t) {
    case AD_VT_UINT: n->kind = 0; n->u = v->u; return 0;
    case AD_VT_INT: n->kind = 1; n->i = v->i; return 0;
    case AD_VT_FLOAT: n->kind = 2; n->f = v->f; return 0;
    case AD_VT_BOOL: n->kind = 3; n->u = v->b; return 0;
    default: return -1;
    }
}

static num num_of_elem(uint8_t dtype, const uint8_t *p)
{
    num n;
    memset(&n, 0, sizeof n);
    if (dtype == 0) { n.kind = 3; n.u = p[0]; }
    else if (dtype >= 9) { n.kind = 2; n.f = ad_load_f64(dtype, p); }
    else if (dtype == 4) { int64_t i; memcpy(&i, p, 8); if (i < 0) { n.kind = 1; n.i = i; } else n.u = (uint64_t)i; }
    else if (dtype == 8) { memcpy(&n.u, p, 8); }
    else { double d = ad_load_f64(dtype, p); if (d < 0) { n.kind = 1; n.i = (int64_t)d; } else n.u = (uint64_t)d; }
    return n;
}

/* Nested msgpack arrays of numbers with exactly `shape` (ndim dims) into dst. */
static int coerce_nested(ad_rd *rd, const ad_val *head, const ad_type *t, uint32_t dim,
                         uint8_t *dst, uint32_t *filled, const char *where, char *why,
                         size_t why_len)
{
    uint32_t want = t->ndim == AD_VARLEN ? head->n : t->shape[dim];
    uint32_t isz = ad_scalar_size(t->base);
    if (head->n != want) {
        ad_snprintf(why, why_len, "%s: expected shape (%u%s) for dimension %u, got %u elements",
                 where, want, "", dim, head->n);
        return 422;
    }
    for (uint32_t k = 0; k < head->n; k++) {
        ad_val v;
        if (ad_rd_next(rd, &v)) { ad_snprintf(why, why_len, "%s: bad array", where); return 422; }
        uint32_t last = t->ndim == AD_VARLEN ? 1 : t->ndim;
        if (dim + 1 < last) {
            if (v.t != AD_VT_ARRAY) {
                ad_snprintf(why, why_len, "%s: expected a %u-D array", where, last);
                return 422;
            }
            int r = coerce_nested(rd, &v, t, dim + 1, dst, filled, where, why, why_len);
            if (r) return r;
            continue;
        }
        num n;
        if (to_num(&v, &n)) {
            ad_snprintf(why, why_len, "%s: expected %s elements, got %s elements", where,
                     SCALARS[t->base], vt_name(v.t));
            return 422;
        }
        int r = store_num(&n, t->base, dst + (size_t)(*filled) * isz, where, 1, why, why_len);
        if (r) return r;
        (*filled)++;
    }
    return 0;
}

int ad_coerce(ad_rd *rd, const ad_type *t, const char *type_text, void *dst, const char *where,
              char *why, size_t why_len)
{
    ad_val v;
    if (ad_rd_next(rd, &v)) { ad_snprintf(why, why_len, "%s: missing value", where); return 422; }
    if (t->base == AD_T_STRUCT) {
        if (v.t != AD_VT_MAP) {
            ad_snprintf(why, why_len, "%s: expected a map for %s, got %s", where, type_text,
                     vt_name(v.t));
            ad_rd_skip_items(rd, &v);
            return 422;
        }
        /* exactly the field names, each once */
        ad_struct_it it;
        const char *fname;
        uint32_t flen, nfields = 0, seen = 0;
        uint8_t fbase;
        ad_struct_begin(&it, type_text);
        while (!ad_struct_next(&it, &fname, &flen, &fbase)) nfields++;
        if (v.n != nfields) {
            ad_snprintf(why, why_len, "%s: expected fields of %s, got %u fields", where, type_text, v.n);
            ad_rd_skip_items(rd, &v);
            return 422;
        }
        for (uint32_t k = 0; k < v.n; k++) {
            ad_val key;
            if (ad_rd_next(rd, &key) || key.t != AD_VT_STR) {
                ad_snprintf(why, why_len, "%s: expected field names", where);
                return 422;
            }
            ad_struct_begin(&it, type_text);
            uint32_t idx = 0, size = 0;
            int found = 0;
            while (1) {
                it.offset = size;
                if (ad_struct_next(&it, &fname, &flen, &fbase)) break;
                if (flen == key.n && !memcmp(fname, key.p, flen)) { found = 1; break; }
                size = it.offset + ad_scalar_size(fbase);
                idx++;
            }
            if (!found || (seen >> idx) & 1u) {
                ad_snprintf(why, why_len, "%s: expected fields of %s, got %.*s", where, type_text,
                         (int)(key.n > 32 ? 32 : key.n), (const char *)key.p);
                return 422;
            }
            seen |= 1u << idx;
            char fwhere[96];
            ad_snprintf(fwhere, sizeof fwhere, "%s.%.*s", where, (int)flen, fname);
            ad_val fv;
            num n;
            if (ad_rd_next(rd, &fv) || to_num(&fv, &n)) {
                ad_snprintf(why, why_len, "%s: expected %s, got %s", fwhere, SCALARS[fbase],
                         vt_name(fv.t));
                return 422;
            }
            int r = store_num(&n, fbase, (uint8_t *)dst + it.offset, fwhere, 0, why, why_len);
            if (r) return r;
        }
        return 0;
    }
    if (t->base == AD_T_STR) {
        if (v.t != AD_VT_STR) {
            ad_snprintf(why, why_len, "%s: expected str, got %s", where, vt_name(v.t));
            ad_rd_skip_items(rd, &v);
            return 422;
        }
        if (v.n + 1 > t->c_size) {
            ad_snprintf(why, why_len, "%s: a str of %u bytes does not fit; at most %u bytes", where,
                     v.n, t->c_size ? t->c_size - 1 : 0);
            return 422;
        }
        memcpy(dst, v.p, v.n);
        ((char *)dst)[v.n] = 0;
        return 0;
    }
    if (t->ndim == 0) {
        num n;
        if (to_num(&v, &n)) {
            ad_snprintf(why, why_len, "%s: expected %s, got %s", where, SCALARS[t->base],
                     vt_name(v.t));
            ad_rd_skip_items(rd, &v);
            return 422;
        }
        return store_num(&n, t->base, dst, where, 0, why, why_len);
    }
    /* fixed arrays (variable ones are function arguments: see the call decoder) */
    if (v.t == AD_VT_EXT && v.ext_type == AD_EXT_NDARRAY) {
        ad_ndarray a;
        ad_parse_ndarray(v.p, v.n, &a);
        int same = a.ndim == t->ndim;
        for (uint8_t d = 0; same && d < a.ndim; d++) same = a.shape[d] == t->shape[d];
        if (!same) {
            ad_snprintf(why, why_len, "%s: expected shape of %s, got an array of %u elements in "
                     "%u dimensions", where, type_text, a.count, a.ndim);
            return 422;
        }
        if (a.dtype == 0 && t->base != 0) {
            ad_snprintf(why, why_len, "%s: expected %s elements, got bool elements", where,
                     SCALARS[t->base]);
            return 422;
        }
        uint32_t isz = ad_scalar_size(t->base), esz = AD_DTYPE_SIZE[a.dtype];
        for (uint32_t k = 0; k < a.count; k++) {
            num n = num_of_elem(a.dtype, a.data + (size_t)k * esz);
            if (a.dtype == 0 && t->base == 0) n.kind = 3;
            int r = store_num(&n, t->base, (uint8_t *)dst + (size_t)k * isz, where, 1, why, why_len);
            if (r) return r;
        }
        return 0;
    }
    if (v.t != AD_VT_ARRAY) {
        ad_snprintf(why, why_len, "%s: expected an array %s, got %s", where, type_text, vt_name(v.t));
        ad_rd_skip_items(rd, &v);
        return 422;
    }
    uint32_t filled = 0;
    return coerce_nested(rd, &v, t, 0, (uint8_t *)dst, &filled, where, why, why_len);
}

void ad_write_value(ad_wr *w, const ad_type *t, const char *type_text, const void *src)
{
    const uint8_t *p = (const uint8_t *)src;
    if (t->base == AD_T_STRUCT) {
        ad_struct_it it;
        const char *fname;
        uint32_t flen, n = 0, size = 0;
        uint8_t fbase;
        ad_struct_begin(&it, type_text);
        while (!ad_struct_next(&it, &fname, &flen, &fbase)) n++;
        ad_wr_map(w, n);
        ad_struct_begin(&it, type_text);
        while (1) {
            it.offset = size;
            if (ad_struct_next(&it, &fname, &flen, &fbase)) break;
            ad_wr_strn(w, fname, flen);
            ad_type ft = {fbase, 0, {0}, 1, ad_scalar_size(fbase)};
            ad_write_value(w, &ft, "", p + it.offset);
            size = it.offset + ad_scalar_size(fbase);
        }
        return;
    }
    if (t->base == AD_T_STR) {
        const uint8_t *nul = memchr(p, 0, t->c_size); /* the buffer may be full, no NUL */
        size_t n = nul ? (size_t)(nul - (const uint8_t *)p) : t->c_size;
        ad_wr_strn(w, (const char *)p, (uint32_t)n);
        return;
    }
    if (t->ndim) {
        uint32_t bytes = t->count * ad_scalar_size(t->base);
        ad_wr_ext(w, AD_EXT_NDARRAY, ad_ndarray_head_bytes(t->ndim) + bytes);
        ad_wr_ndarray_head(w, t->base, t->ndim, t->shape);
        ad_wr_raw(w, p, bytes); /* little-endian hosts and MCUs: the C layout is the wire's */
        return;
    }
    switch (t->base) {
    case 0: ad_wr_bool(w, p[0] != 0); break;
    case 9: ad_wr_f64(w, ad_load_f64(9, p)); break;
    case 10: ad_wr_f64(w, ad_load_f64(10, p)); break;
    case 8: { uint64_t u; memcpy(&u, p, 8); ad_wr_uint(w, u); break; }
    case 5: case 6: case 7: ad_wr_uint(w, (uint64_t)ad_load_f64(t->base, p)); break;
    default: ad_wr_int(w, ad_load_i64(t->base, p)); break;
    }
}
