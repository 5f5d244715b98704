/* msgpack for ASTCom frames: libmpack reads, msgpack-c writes (see ad_codec.h).
 *
 * Why two libraries. Reading hostile frames on a device needs a parser that hands out
 * one token at a time without allocating, so every declared length and count can be
 * checked against the limits before anything is trusted: libmpack's tokenizer does
 * exactly that. msgpack-c's C unpacker instead allocates its objects in a zone sized by
 * the counts the peer declares, and has no limits. For writing, msgpack-c's packer is
 * the reference (header-only, allocation-free through a write callback); libmpack's
 * writer picks the wrong format for some negative integers (-129 comes out as +127).
 */
#include "ad_codec.h"
#include "astcom_device.h"

#include <stdio.h>
#include <string.h>

#include <msgpack/pack.h>

const uint8_t AD_DTYPE_SIZE[11] = {1, 1, 2, 4, 8, 1, 2, 4, 8, 4, 8};

/* ---- strict UTF-8 --------------------------------------------------------------------- */
int ad_utf8_valid(const uint8_t *p, size_t n)
{
    size_t i = 0;
    while (i < n) {
        uint8_t c = p[i];
        uint32_t cp, need, min;
        if (c < 0x80) { i++; continue; }
        if ((c & 0xe0) == 0xc0) { need = 1; cp = c & 0x1f; min = 0x80; }
        else if ((c & 0xf0) == 0xe0) { need = 2; cp = c & 0x0f; min = 0x800; }
        else if ((c & 0xf8) == 0xf0) { need = 3; cp = c & 0x07; min = 0x10000; }
        else return 0;
        if (n - i - 1 < need) return 0;
        for (uint32_t k = 1; k <= need; k++) {
            if ((p[i + k] & 0xc0) != 0x80) return 0;
            cp = (cp << 6) | (p[i + k] & 0x3f);
        }
        if (cp < min || cp > 0x10ffff || (cp >= 0xd800 && cp <= 0xdfff)) return 0;
        i += need + 1;
    }
    return 1;
}

/* ---- ext 1 ---------------------------------------------------------------------------- */
uint32_t ad_ndarray_head_bytes(uint8_t ndim)
{
    return (4u + 4u * ndim + 7u) / 8u * 8u;
}

static uint32_t le32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

int ad_parse_ndarray(const uint8_t *p, uint32_t n, ad_ndarray *out)
{
    if (n < 4 || p[0] > 10 || p[1] > AD_MAX_NDIM || p[2] || p[3]) return -1;
    uint32_t head = ad_ndarray_head_bytes(p[1]);
    if (n < head) return -1;
    uint64_t count = 1;
    out->dtype = p[0];
    out->ndim = p[1];
    for (uint8_t d = 0; d < out->ndim; d++) {
        out->shape[d] = le32(p + 4 + 4 * d);
        count *= out->shape[d];
        if (count > 0xffffffffu) return -1;
    }
    if ((uint64_t)(n - head) != count * AD_DTYPE_SIZE[out->dtype]) return -1;
    out->count = (uint32_t)count;
    out->data = p + head;
    if (out->dtype == 0)
        for (uint32_t k = 0; k < out->count; k++)
            if (out->data[k] > 1) return -1;
    return 0;
}

/* ---- the validating walk --------------------------------------------------------------- */
#define ERR(code, ...) do { ad_snprintf(why, why_len, __VA_ARGS__); return (code); } while (0)

int ad_validate(const uint8_t *frame, size_t len, const ad_limits *lim, char *why,
                size_t why_len)
{
    /* remaining[d]: items still expected at depth d; map levels count keys and values */
    uint32_t remaining[33];
    uint8_t is_map[33];
    uint32_t depth = 0;
    uint32_t max_depth = lim->max_depth > 32 ? 32 : lim->max_depth;
    mpack_tokbuf_t tb;
    mpack_token_t tok;
    const char *p = (const char *)frame;
    size_t left = len;

    if (len > lim->max_frame_bytes)
        ERR(413, "frame of %zu bytes exceeds the limit of %u bytes", len, lim->max_frame_bytes);
    mpack_tokbuf_init(&tb);
    remaining[0] = 1;
    is_map[0] = 0;
    while (remaining[0] || depth > 0) {
        int key = is_map[depth] && remaining[depth] % 2 == 0;
        if (left == 0)
            ERR(400, "frame ends inside a msgpack value: a value declares more bytes than "
                     "the frame holds (truncated frame)");
        int st = mpack_read(&tb, &p, &left, &tok);
        if (st == MPACK_EOF)
            ERR(400, "frame ends inside a msgpack value: a value declares more bytes than "
                     "the frame holds (truncated frame)");
        if (st != MPACK_OK)
            ERR(400, "frame is not valid msgpack: byte 0x%02x at offset %zu is no msgpack "
                     "type", (unsigned)(uint8_t)p[-1], (size_t)(p - (const char *)frame) - 1);
        if (key && tok.type != MPACK_TOKEN_STR && tok.type != MPACK_TOKEN_BIN)
            ERR(400, "frame is not valid msgpack: map keys must be strings");
        remaining[depth]--;
        switch (tok.type) {
        case MPACK_TOKEN_ARRAY:
        case MPACK_TOKEN_MAP: {
            int map = tok.type == MPACK_TOKEN_MAP;
            if (tok.length > lim->max_array_len)
                ERR(413, "frame exceeds a size limit: %u exceeds max_%s_len(%u)", tok.length,
                    map ? "map" : "array", lim->max_array_len);
            if (depth + 1 > max_depth)
                ERR(413, "frame nests deeper than %u levels", lim->max_depth);
            if (tok.length) {
                depth++;
                remaining[depth] = map ? 2 * tok.length : tok.length;
                is_map[depth] = (uint8_t)map;
            }
            break;
        }
        case MPACK_TOKEN_STR:
        case MPACK_TOKEN_BIN:
        case MPACK_TOKEN_EXT: {
            uint32_t n = tok.length;
            int ext_type = tok.type == MPACK_TOKEN_EXT ? tok.data.ext_type : -1;
            if (n > left)
                ERR(400, "frame ends inside a msgpack value: a str, bin or ext declares more "
                         "bytes than the frame holds (truncated frame)");
            const uint8_t *body = (const uint8_t *)p;
            if (n) {
                mpack_token_t chunk;
                mpack_read(&tb, &p, &left, &chunk); /* the whole payload: it is in the frame */
            }
            if (tok.type == MPACK_TOKEN_STR) {
                if (n > lim->max_str_bytes)
                    ERR(413, "frame exceeds a size limit: %u exceeds max_str_len(%u)", n,
                        lim->max_str_bytes);
                if (!ad_utf8_valid(body, n))
                    ERR(400, "frame is not valid msgpack: a str is not valid UTF-8");
            } else if (tok.type == MPACK_TOKEN_EXT) {
                if (ext_type == AD_EXT_NDARRAY) {
                    ad_ndarray arr;
                    if (n >= 4 && n >= ad_ndarray_head_bytes(body[1] > 8 ? 8 : body[1])
                            && body[0] <= 10 && body[1] <= 8 && !body[2] && !body[3]) {
                        uint64_t count = 1;
                        for (uint8_t d = 0; d < body[1]; d++) count *= le32(body + 4 + 4 * d);
                        if (count > lim->max_array_len)
                            ERR(413, "ndarray of %llu elements exceeds the limit of %u",
                                (unsigned long long)count, lim->max_array_len);
                    }
                    if (ad_parse_ndarray(body, n, &arr))
                        ERR(400, "malformed ndarray extension (ext 1): header, reserved field, "
                                 "length or bool bytes wrong");
                } else if (ext_type == AD_EXT_TIMESTAMP) {
                    if (n != 8)
                        ERR(400, "timestamp extension holds %u bytes, expected 8", n);
                } else {
                    ERR(400, "unknown extension type %d; known: 1 (ndarray), 2 (timestamp)",
                        ext_type);
                }
            }
            break;
        }
        default:
            break;
        }
        while (depth > 0 && remaining[depth] == 0) depth--;
    }
    if (left)
        ERR(400, "frame holds %zu extra bytes after its msgpack value (exactly one value "
                 "per frame)", left);
    return 0;
}
#undef ERR

/* ---- reading ---------------------------------------------------------------------------- */
void ad_rd_init(ad_rd *rd, const uint8_t *frame, size_t len)
{
    rd->p = (const char *)frame;
    rd->left = len;
    mpack_tokbuf_init(&rd->tb);
}

int ad_rd_next(ad_rd *rd, ad_val *v)
{
    mpack_token_t tok;
    memset(v, 0, sizeof *v);
    if (!rd->left || mpack_read(&rd->tb, &rd->p, &rd->left, &tok) != MPACK_OK) return -1;
    switch (tok.type) {
    case MPACK_TOKEN_NIL: v->t = AD_VT_NIL; break;
    case MPACK_TOKEN_BOOLEAN: v->t = AD_VT_BOOL; v->b = (uint8_t)mpack_unpack_boolean(tok); break;
    case MPACK_TOKEN_UINT: v->t = AD_VT_UINT; v->u = mpack_unpack_uint(tok); break;
    case MPACK_TOKEN_SINT: v->t = AD_VT_INT; v->i = mpack_unpack_sint(tok); break;
    case MPACK_TOKEN_FLOAT:
        v->t = AD_VT_FLOAT;
        v->float_bytes = (uint8_t)tok.length;
        v->f = mpack_unpack_float(tok);
        break;
    case MPACK_TOKEN_ARRAY: v->t = AD_VT_ARRAY; v->n = tok.length; break;
    case MPACK_TOKEN_MAP: v->t = AD_VT_MAP; v->n = tok.length; break;
    case MPACK_TOKEN_STR:
    case MPACK_TOKEN_BIN:
    case MPACK_TOKEN_EXT:
        v->t = tok.type == MPACK_TOKEN_STR ? AD_VT_STR
             : tok.type == MPACK_TOKEN_BIN ? AD_VT_BIN : AD_VT_EXT;
        v->ext_type = tok.type == MPACK_TOKEN_EXT ? (int8_t)tok.data.ext_type : 0;
        v->n = tok.length;
        v->p = (const uint8_t *)rd->p;
        if (tok.length) {
            mpack_token_t chunk;
            if (rd->left < tok.length || mpack_read(&rd->tb, &rd->p, &rd->left, &chunk) != MPACK_OK
                    || chunk.length != tok.length)
                return -1;
        }
        break;
    default:
        return -1;
    }
    return 0;
}

int ad_rd_skip_items(ad_rd *rd, const ad_val *v)
{
    /* iterative: a validated frame nests at most max_depth (≤ 32) levels, but counting
     * keeps the stack flat anyway */
    uint64_t pending = v->t == AD_VT_ARRAY ? v->n : v->t == AD_VT_MAP ? 2ull * v->n : 0;
    while (pending) {
        ad_val item;
        if (ad_rd_next(rd, &item)) return -1;
        pending--;
        if (item.t == AD_VT_ARRAY) pending += item.n;
        else if (item.t == AD_VT_MAP) pending += 2ull * item.n;
    }
    return 0;
}

int ad_rd_skip(ad_rd *rd)
{
    ad_val v;
    if (ad_rd_next(rd, &v)) return -1;
    return ad_rd_skip_items(rd, &v);
}

/* ---- writing ---------------------------------------------------------------------------- */
static int wr_cb(void *data, const char *buf, size_t len)
{
    ad_wr *w = (ad_wr *)data;
    if (w->spill && len > w->left) {
        ad_wr_flush(w);
        if (len > w->left) { /* larger than the whole window: straight through */
            w->spill(w->spill_ctx, (const uint8_t *)buf, len);
            w->used += len;
            return 0;
        }
    }
    if (!w->overflow && len <= w->left) {
        memcpy(w->p, buf, len);
        w->p += len;
        w->left -= len;
    } else {
        w->overflow = 1;
    }
    w->used += len;
    return 0;
}

#define PK(w) msgpack_packer pk; msgpack_packer_init(&pk, (w), wr_cb)

void ad_wr_init(ad_wr *w, uint8_t *buf, size_t cap)
{
    ad_wr_init_spill(w, buf, cap, NULL, NULL);
}

void ad_wr_init_spill(ad_wr *w, uint8_t *buf, size_t cap, ad_spill_fn spill, void *ctx)
{
    w->p = w->base = (char *)buf;
    w->left = w->cap = cap;
    w->used = 0;
    w->overflow = 0;
    w->spill = spill;
    w->spill_ctx = ctx;
}

void ad_wr_flush(ad_wr *w)
{
    if (w->spill && w->p > w->base) w->spill(w->spill_ctx, (const uint8_t *)w->base, (size_t)(w->p - w->base));
    w->p = w->base;
    w->left = w->cap;
}

void ad_wr_array(ad_wr *w, uint32_t n) { PK(w); msgpack_pack_array(&pk, n); }
void ad_wr_map(ad_wr *w, uint32_t n) { PK(w); msgpack_pack_map(&pk, n); }
void ad_wr_strn(ad_wr *w, const char *s, uint32_t n)
{
    PK(w);
    msgpack_pack_str(&pk, n);
    if (n) msgpack_pack_str_body(&pk, s, n);
}
void ad_wr_str(ad_wr *w, const char *s) { ad_wr_strn(w, s, (uint32_t)strlen(s)); }
void ad_wr_bin(ad_wr *w, const uint8_t *p, uint32_t n)
{
    PK(w);
    msgpack_pack_bin(&pk, n);
    if (n) msgpack_pack_bin_body(&pk, p, n);
}
/* Integers in the smallest format; non-negative ones as uint, as msgpack-python does. */
void ad_wr_uint(ad_wr *w, uint64_t v) { PK(w); msgpack_pack_uint64(&pk, v); }
void ad_wr_int(ad_wr *w, int64_t v)
{
    PK(w);
    if (v >= 0) msgpack_pack_uint64(&pk, (uint64_t)v);
    else msgpack_pack_int64(&pk, v);
}
void ad_wr_f64(ad_wr *w, double v) { PK(w); msgpack_pack_double(&pk, v); }
void ad_wr_bool(ad_wr *w, int v)
{
    PK(w);
    if (v) msgpack_pack_true(&pk); else msgpack_pack_false(&pk);
}
void ad_wr_nil(ad_wr *w) { PK(w); msgpack_pack_nil(&pk); }
void ad_wr_ext(ad_wr *w, int type, uint32_t n) { PK(w); msgpack_pack_ext(&pk, n, (int8_t)type); }
void ad_wr_raw(ad_wr *w, const void *p, uint32_t n) { wr_cb(w, (const char *)p, n); }

void ad_wr_ndarray_head(ad_wr *w, uint8_t dtype, uint8_t ndim, const uint32_t *shape)
{
    uint8_t head[4 + 4 * AD_MAX_NDIM + 4] = {0};
    uint32_t h = ad_ndarray_head_bytes(ndim);
    head[0] = dtype;
    head[1] = ndim;
    for (uint8_t d = 0; d < ndim; d++) {
        head[4 + 4 * d] = (uint8_t)shape[d];
        head[5 + 4 * d] = (uint8_t)(shape[d] >> 8);
        head[6 + 4 * d] = (uint8_t)(shape[d] >> 16);
        head[7 + 4 * d] = (uint8_t)(shape[d] >> 24);
    }
    ad_wr_raw(w, head, h);
}

void ad_wr_timestamp(ad_wr *w, int64_t t_us)
{
    uint8_t b[8];
    uint64_t u = (uint64_t)t_us;
    for (int k = 0; k < 8; k++) b[k] = (uint8_t)(u >> (8 * k));
    ad_wr_ext(w, AD_EXT_TIMESTAMP, 8);
    ad_wr_raw(w, b, 8);
}
