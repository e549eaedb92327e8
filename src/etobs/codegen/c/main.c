/* A minimal main loop around the generated node (etobs). Replace the four callbacks with
 * your board's radio, flash, clock and sensor; the rest stays as it is.
 *
 * On a host, `cc -std=c99 main.c etobs_node.c etobs_sha256.c -lm` builds it as a demo: the
 * clock is simulated, the "radio" counts packets, and it stops after 1000 samples. */
#include <stdio.h>
#include <string.h>

#include "etobs_node.h"

static double fake_time;      /* seconds since the deployment's epoch (your RTC or timer) */
static unsigned long packets; /* what the "radio" sent */

static int radio_send(void *ctx, const uint8_t *data, size_t len) {
    (void)ctx;
    (void)data;
    (void)len; /* your radio: send the datagram to the observer service (UDP) */
    packets++;
    return 0;
}

static int flash_store(void *ctx, uint64_t bound) {
    (void)ctx;
    (void)bound; /* your flash: write `bound` durably; read it back at boot (etobs_node_init) */
    return 0;
}

static double clock_seconds(void *ctx) {
    (void)ctx; /* your clock: seconds since the epoch the service gave (etobs serve --epoch) */
    return fake_time;
}

static int read_outputs(void *ctx, double y[ETOBS_N_VALUES]) {
    unsigned i;
    (void)ctx; /* your sensor: the node's outputs, in the units of the model */
    for (i = 0; i < ETOBS_N_VALUES; i++) y[i] = 20.0 * fake_time; /* a ramp */
    return 0;
}

int main(void) {
    static const uint8_t key[32] = {0}; /* provision the node's key (HMAC-SHA256(secret, "etobs-node-<id>")) */
    etobs_node node;
    etobs_io io;
    int r;
    memset(&io, 0, sizeof io);
    io.send = radio_send;
    io.store_bound = flash_store;
    io.clock = clock_seconds;
    io.read = read_outputs;
    io.ctx = NULL;
    /* session: the deployment's epoch; 0: the bound read from flash at boot; 0: first sample */
    if (etobs_node_init(&node, &io, key, 1700000000.0, 0, 0) != 0) return 1;
    while (node.k_next < 1000) {
        r = etobs_node_poll(&node); /* takes the sample when it is due */
        if (r < 0) return 1;        /* a callback failed: see etobs_node.h */
        fake_time += ETOBS_PERIOD / 4; /* your board: sleep until the next timer interrupt */
    }
    printf("main: 1000 samples, %u transmissions, %lu packets\n", (unsigned)node.transmissions, packets);
    return 0;
}
