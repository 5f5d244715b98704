/* Challenge–response (§5) with mbedTLS's HMAC-SHA256; constant-time comparison. */
#include <string.h>

#include <mbedtls/md.h>

#include "ad_internal.h"

int ad_hmac(const char *password, const char *label, const uint8_t *sn, size_t sn_len,
            const uint8_t *cn, size_t cn_len, uint8_t out[32])
{
    const mbedtls_md_info_t *info = mbedtls_md_info_from_type(MBEDTLS_MD_SHA256);
    mbedtls_md_context_t ctx;
    int rc;
    if (!info) return -1;
    mbedtls_md_init(&ctx);
    /* hmac=1: the context keeps the HMAC pads; with MBEDTLS_MD_C on a static build this
     * uses mbedTLS's calloc once per call (see docs/astcom-device.md, "Memory") */
    rc = mbedtls_md_setup(&ctx, info, 1);
    if (!rc) rc = mbedtls_md_hmac_starts(&ctx, (const unsigned char *)password, strlen(password));
    /* the label is the 15 ASCII bytes followed by one zero byte */
    if (!rc) rc = mbedtls_md_hmac_update(&ctx, (const unsigned char *)label, strlen(label) + 1);
    if (!rc) rc = mbedtls_md_hmac_update(&ctx, sn, sn_len);
    if (!rc) rc = mbedtls_md_hmac_update(&ctx, cn, cn_len);
    if (!rc) rc = mbedtls_md_hmac_finish(&ctx, out);
    mbedtls_md_free(&ctx);
    return rc ? -1 : 0;
}

int ad_equal_ct(const uint8_t *a, const uint8_t *b, size_t n)
{
    uint8_t diff = 0;
    for (size_t i = 0; i < n; i++) diff |= (uint8_t)(a[i] ^ b[i]);
    return diff == 0;
}
