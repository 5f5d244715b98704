/* msgpack for ASTCom frames over libmpack's tokenizer (caller-owned buffers, no heap).
 *
 * Reading is two passes over a whole frame held by the caller: ad_validate() walks every
 * token once and enforces the spec's limits in byte order (§7 "Which error wins"); the
 * request decoder then walks the validated frame with ad_rd_*. Writing goes token by
 * token into a caller buffer; a writer that runs out of room only counts (so the same
 * code measures a frame's size).
 */
#ifndef AD_CODEC_H
#define AD_CODEC_H

#include <stddef.h>
#include <stdint.h>

#include <mpack.h>

#define AD_EXT_NDARRAY 1
#define AD_EXT_TIMESTAMP 2
#define AD_MAX_NDIM 8

typedef struct ad_limits {
    uint32_t max_frame_bytes, max_depth, max_array_len, max_str_bytes;
} ad_limits;

/* 0, or 400/413 with a message in why[why_len]. */
int ad_validate(const uint8_t *frame, size_t len, const ad_limits *lim, char *why,
                size_t why_len);

/* ---- reading a validated frame --------------------------------------------------------- */

enum ad_vt {
    AD_VT_NIL, AD_VT_BOOL, AD_VT_UINT, AD_VT_INT, AD_VT_FLOAT, AD_VT_STR, AD_VT_BIN,
    AD_VT_ARRAY, AD_VT_MAP, AD_VT_EXT
};

/* One decoded value head: scalars are complete; str/bin/ext carry their bytes; array
 * and map carry their count (their items follow in the reader). */
typedef struct ad_val {
    uint8_t t;              /* enum ad_vt */
    int8_t ext_type;
    uint8_t b;
    uint8_t float_bytes;    /* 4 or 8 for AD_VT_FLOAT */
    uint64_t u;             /* AD_VT_UINT */
    int64_t i;              /* AD_VT_INT (negative) */
    double f;
    const uint8_t *p;       /* str/bin/ext bytes */
    uint32_t n;             /* str/bin/ext length, array/map count */
} ad_val;

typedef struct ad_rd {
    const char *p;
    size_t left;
    mpack_tokbuf_t tb;
} ad_rd;

void ad_rd_init(ad_rd *rd, const uint8_t *frame, size_t len);
/* Read the next value head; 0 on success, -1 at the end or on bad bytes. */
int ad_rd_next(ad_rd *rd, ad_val *v);
/* Skip the items of a container whose head was just read (v), recursively. */
int ad_rd_skip_items(ad_rd *rd, const ad_val *v);
int ad_rd_skip(ad_rd *rd);

/* An ext 1 array's header, parsed: dtype code, shape, element bytes. */
typedef struct ad_ndarray {
    uint8_t dtype, ndim;
    uint32_t shape[AD_MAX_NDIM];
    uint32_t count;
    const uint8_t *data;
} ad_ndarray;
/* 0, or -1 when the payload is not a well-formed ext 1 array. */
int ad_parse_ndarray(const uint8_t *p, uint32_t n, ad_ndarray *out);
extern const uint8_t AD_DTYPE_SIZE[11];

/* ---- writing ------------------------------------------------------------------------------ */

/* A frame being written into a buffer. With a spill function the buffer is a window: when
 * it is full its bytes go to spill() and writing goes on (a frame larger than the buffer,
 * sent in parts); without, bytes past its end are only counted (overflow). */
typedef void (*ad_spill_fn)(void *ctx, const uint8_t *bytes, size_t n);
typedef struct ad_wr {
    char *p;
    size_t left;
    size_t used;       /* bytes the frame takes, counted even past the end of the buffer */
    int overflow;
    char *base;
    size_t cap;
    ad_spill_fn spill;
    void *spill_ctx;
} ad_wr;

void ad_wr_init(ad_wr *w, uint8_t *buf, size_t cap);
void ad_wr_init_spill(ad_wr *w, uint8_t *buf, size_t cap, ad_spill_fn spill, void *ctx);
/* Hand the bytes still in the window to spill() (the frame's last part). */
void ad_wr_flush(ad_wr *w);
void ad_wr_array(ad_wr *w, uint32_t n);
void ad_wr_map(ad_wr *w, uint32_t n);
void ad_wr_str(ad_wr *w, const char *s);
void ad_wr_strn(ad_wr *w, const char *s, uint32_t n);
void ad_wr_bin(ad_wr *w, const uint8_t *p, uint32_t n);
void ad_wr_uint(ad_wr *w, uint64_t v);
void ad_wr_int(ad_wr *w, int64_t v);
void ad_wr_f64(ad_wr *w, double v);
void ad_wr_bool(ad_wr *w, int v);
void ad_wr_nil(ad_wr *w);
/* An ext header of `n` payload bytes; the payload follows with ad_wr_raw. */
void ad_wr_ext(ad_wr *w, int type, uint32_t n);
void ad_wr_raw(ad_wr *w, const void *p, uint32_t n);
/* The header of an ext 1 array of `dtype` and `shape` (C order): H bytes. */
void ad_wr_ndarray_head(ad_wr *w, uint8_t dtype, uint8_t ndim, const uint32_t *shape);
uint32_t ad_ndarray_head_bytes(uint8_t ndim);
void ad_wr_timestamp(ad_wr *w, int64_t t_us);
/* A key-value pair of a map with a str key. */
#define AD_KEY(w, k) ad_wr_str((w), (k))

/* Strict UTF-8 (no overlongs, no surrogates, at most U+10FFFF): 1 when valid. */
int ad_utf8_valid(const uint8_t *p, size_t n);

#endif
