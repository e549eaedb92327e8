/* Time per sample of a generated node (etobs `codegen c`): the samples of a vector file,
 * read into memory, then the node run over them.
 *
 *   c_node_bench VECTORS REPEATS
 *
 * On the host (-DETOBS_HOST_CLOCK) the wall time of the loop (clock_gettime). On a Cortex-M
 * under QEMU with -icount shift=0 (-DETOBS_SYSTICK) the SysTick counter, read before and
 * after each sample (24 bits: each sample is far shorter than a wrap), and a calibration
 * loop of 200,000 instructions (100,000 times subs, bne) that gives instructions per tick. Prints one line of figures. */
#if defined(ETOBS_HOST_CLOCK)
#define _POSIX_C_SOURCE 200809L
#include <time.h>
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "etobs_node.h"

#define MAXS 100001
static double ys[MAXS][ETOBS_N_VALUES];
static uint64_t ks[MAXS];
static char line[16384];
static unsigned long packets;

static int count(void *ctx, const uint8_t *d, size_t n) {
    (void)ctx;
    (void)d;
    (void)n;
    packets++;
    return 0;
}
static int store(void *ctx, uint64_t b) {
    (void)ctx;
    (void)b;
    return 0;
}

#if defined(ETOBS_SYSTICK)
#define SYST_CSR (*(volatile uint32_t *)0xE000E010u)
#define SYST_RVR (*(volatile uint32_t *)0xE000E014u)
#define SYST_CVR (*(volatile uint32_t *)0xE000E018u)
static uint32_t now_ticks(void) { return SYST_CVR; } /* counts down */
static uint32_t since(uint32_t start) { return (start - SYST_CVR) & 0xFFFFFFu; }
#elif defined(ETOBS_HOST_CLOCK)
static double wall(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}
#endif

int main(int argc, char **argv) {
    FILE *f;
    etobs_node node;
    etobs_io io;
    uint8_t key[32] = {0};
    long n = 0, r, i, reps;
    unsigned long sent = 0;
    if (argc != 3) return 2;
    reps = atol(argv[2]);
    f = fopen(argv[1], "r");
    if (f == NULL) return 2;
    while (fgets(line, sizeof line, f) != NULL && n < MAXS) {
        char *tok = strtok(line, " \n");
        if (tok == NULL || strcmp(tok, "sample") != 0) continue;
        ks[n] = strtoull(strtok(NULL, " \n"), NULL, 10);
        for (i = 0; i < (long)ETOBS_N_VALUES; i++) ys[n][i] = strtod(strtok(NULL, " \n"), NULL);
        n++;
    }
    fclose(f);
    memset(&io, 0, sizeof io);
    io.send = count;
    io.store_bound = store;
#if defined(ETOBS_SYSTICK)
    {
        uint64_t ticks = 0, cal;
        uint32_t t0;
        SYST_RVR = 0xFFFFFFu;
        SYST_CVR = 0;
        SYST_CSR = 5u; /* enable, processor clock, no interrupt */
        {
            uint32_t left = 100000u; /* 2 instructions an iteration: subs, bne */
            t0 = now_ticks();
            __asm volatile("1: subs %0, %0, #1\n\tbne 1b" : "+r"(left));
            cal = since(t0);
        }
        for (r = 0; r < reps; r++) {
            etobs_node_init(&node, &io, key, 1.7e9, 0, 0);
            for (i = 0; i < n; i++) {
                t0 = now_ticks();
                etobs_node_sample(&node, ks[i], ys[i]);
                ticks += since(t0);
            }
            sent += node.transmissions;
        }
        printf("bench: samples=%ld repeats=%ld transmissions=%lu ticks_per_sample=%.2f calibration_ticks=%lu "
               "state_bytes=%u\n",
               n, reps, sent, (double)ticks / (double)(n * reps), (unsigned long)cal, (unsigned)sizeof(etobs_node));
    }
#else
    {
        double t0 = wall(), dt;
        for (r = 0; r < reps; r++) {
            etobs_node_init(&node, &io, key, 1.7e9, 0, 0);
            for (i = 0; i < n; i++) etobs_node_sample(&node, ks[i], ys[i]);
            sent += node.transmissions;
        }
        dt = wall() - t0;
        printf("bench: samples=%ld repeats=%ld transmissions=%lu ns_per_sample=%.1f state_bytes=%u\n", n, reps, sent,
               1e9 * dt / (double)(n * reps), (unsigned)sizeof(etobs_node));
    }
#endif
    (void)packets;
    return 0;
}
