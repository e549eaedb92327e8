/* SHA-256 (FIPS 180-4) and HMAC-SHA256 (RFC 2104): self-contained C99, no malloc, no libm.
 * Part of etobs (BSD-3-Clause licence, see LICENSE in this folder). */
#ifndef ETOBS_SHA256_H
#define ETOBS_SHA256_H

#include <stddef.h>
#include <stdint.h>

typedef struct {
    uint32_t h[8];
    uint64_t length; /* bytes hashed so far */
    uint8_t block[64];
    size_t used; /* bytes in block */
} etobs_sha256;

void etobs_sha256_init(etobs_sha256 *s);
void etobs_sha256_update(etobs_sha256 *s, const uint8_t *data, size_t n);
void etobs_sha256_final(etobs_sha256 *s, uint8_t digest[32]);

/* HMAC-SHA256 of data under key (any length; a key longer than 64 bytes is hashed first). */
void etobs_hmac_sha256(const uint8_t *key, size_t key_len, const uint8_t *data, size_t n, uint8_t mac[32]);

#endif
