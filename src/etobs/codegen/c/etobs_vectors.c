/* Replay a conformance vector file through the generated node and compare (etobs).
 *
 *   etobs_vectors VECTORS [TOLERANCE]
 *
 * Each sample line gives the outputs the Python sensor node read and what it did: whether
 * it fired, its filter after the sample, its trigger function and the trigger's threshold
 * scale, and the packets it sent (hex). The node here takes the same samples. Printed:
 *   vectors: samples=.. decisions_equal=.. decision_mismatches=.. worst_margin=.. eta_equal=..
 *            max_eta_drift=.. packets_equal=.. packets_differ=.. transmissions=..
 * float64: every decision, eta and packet byte must be equal (exit 0). float32: a decision may
 * differ where |g| <= TOLERANCE * scale (the Python trigger's distance to its threshold,
 * relative); the node then takes the Python node's state back, and packets are compared
 * where the decisions agree. Runs on the host and on a Cortex-M under QEMU (semihosting). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "etobs_node.h"

#define MAX_PACKETS 4
#define LINE 16384

static uint8_t got[MAX_PACKETS][ETOBS_PACKET_MAX];
static size_t got_len[MAX_PACKETS];
static int n_got;

static int capture(void *ctx, const uint8_t *data, size_t len) {
    (void)ctx;
    if (n_got < MAX_PACKETS) {
        memcpy(got[n_got], data, len);
        got_len[n_got] = len;
    }
    n_got++;
    return 0;
}

static int store(void *ctx, uint64_t bound) {
    (void)ctx;
    (void)bound;
    return 0;
}

static int hexbyte(const char *s) {
    int v = 0, i;
    for (i = 0; i < 2; i++) {
        char c = s[i];
        v = v * 16 + (c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : c - 'A' + 10);
    }
    return v;
}

static size_t unhex(const char *s, uint8_t *out, size_t max) {
    size_t n = strlen(s) / 2, i;
    if (n > max) n = max;
    for (i = 0; i < n; i++) out[i] = (uint8_t)hexbyte(s + 2 * i);
    return n;
}

static char line[LINE];

int main(int argc, char **argv) {
    FILE *f;
    etobs_node node;
    etobs_io io;
    uint8_t key[32];
    double session = 0, tolerance = 0, worst = 0, drift = 0;
    unsigned node_id = 0, n_values = 0;
    long samples = 0, dec_eq = 0, dec_ne = 0, eta_eq = 0, pk_eq = 0, pk_ne = 0, bad = 0;
    int ok;
    if (argc < 2) {
        fprintf(stderr, "usage: etobs_vectors VECTORS [TOLERANCE]\n");
        return 2;
    }
    if (argc > 2) tolerance = strtod(argv[2], NULL);
    f = fopen(argv[1], "r");
    if (f == NULL) {
        fprintf(stderr, "etobs_vectors: cannot open %s\n", argv[1]);
        return 2;
    }
    memset(&io, 0, sizeof io);
    io.send = capture;
    io.store_bound = store;
    ok = 0;
    while (fgets(line, sizeof line, f) != NULL) {
        char *tok = strtok(line, " \n");
        if (tok == NULL || tok[0] == '#') continue;
        if (strcmp(tok, "node") == 0) {
            node_id = (unsigned)strtoul(strtok(NULL, " \n"), NULL, 10);
            strtok(NULL, " \n"); /* values */
            n_values = (unsigned)strtoul(strtok(NULL, " \n"), NULL, 10);
            strtok(NULL, " \n"); /* session */
            session = strtod(strtok(NULL, " \n"), NULL);
            strtok(NULL, " \n"); /* key */
            unhex(strtok(NULL, " \n"), key, 32);
            if (node_id != ETOBS_NODE_ID || n_values != ETOBS_N_VALUES) {
                fprintf(stderr, "etobs_vectors: vectors of node %u (%u values); this node is %u (%u)\n", node_id,
                        n_values, ETOBS_NODE_ID, ETOBS_N_VALUES);
                return 2;
            }
            if (etobs_node_init(&node, &io, key, session, 0, 0) != 0) return 2;
            ok = 1;
        } else if (strcmp(tok, "sample") == 0 && ok) {
            double y[ETOBS_N_VALUES], eta, g, scale;
            uint8_t want[MAX_PACKETS][ETOBS_PACKET_MAX];
            size_t want_len[MAX_PACKETS];
            int fire, n_want, i, r, fired;
            uint64_t k = strtoull(strtok(NULL, " \n"), NULL, 10);
            for (i = 0; i < (int)ETOBS_N_VALUES; i++) y[i] = strtod(strtok(NULL, " \n"), NULL);
            strtok(NULL, " \n");
            fire = atoi(strtok(NULL, " \n"));
            strtok(NULL, " \n");
            eta = strtod(strtok(NULL, " \n"), NULL);
            strtok(NULL, " \n");
            g = strtod(strtok(NULL, " \n"), NULL);
            strtok(NULL, " \n");
            scale = strtod(strtok(NULL, " \n"), NULL);
            strtok(NULL, " \n");
            n_want = atoi(strtok(NULL, " \n"));
            for (i = 0; i < n_want && i < MAX_PACKETS; i++) want_len[i] = unhex(strtok(NULL, " \n"), want[i], ETOBS_PACKET_MAX);
            n_got = 0;
            r = etobs_node_sample(&node, k, y);
            if (r < 0) {
                fprintf(stderr, "etobs_vectors: sample %llu: error %d\n", (unsigned long long)k, r);
                return 1;
            }
            samples++;
            fired = r == ETOBS_SENT;
            if (fired == fire) {
                dec_eq++;
                if (n_got == n_want) {
                    for (i = 0; i < n_want; i++) {
                        if (got_len[i] == want_len[i] && memcmp(got[i], want[i], want_len[i]) == 0)
                            pk_eq++;
                        else
                            pk_ne++;
                    }
                } else {
                    pk_ne += n_want > n_got ? n_want : n_got;
                }
            } else {
                double margin = fabs(g) / (scale > 0 ? scale : 1.0);
                dec_ne++;
                if (margin > worst) worst = margin;
                if (margin > tolerance) bad++;
                /* take the Python node's state back: what it sent and its sequence numbers */
                if (fire) memcpy(node.sent, y, sizeof node.sent);
                node.seq_next += (uint64_t)n_want - (uint64_t)n_got;
            }
            if ((double)node.eta == eta)
                eta_eq++;
            else {
                double d = fabs((double)node.eta - eta) / (fabs(eta) > 1.0 ? fabs(eta) : 1.0);
                if (d > drift) drift = d;
                if (fired != fire) node.eta = (etobs_real)eta;
            }
        }
    }
    fclose(f);
    printf("vectors: samples=%ld decisions_equal=%ld decision_mismatches=%ld worst_margin=%.3e eta_equal=%ld "
           "max_eta_drift=%.3e packets_equal=%ld packets_differ=%ld transmissions=%lu\n",
           samples, dec_eq, dec_ne, worst, eta_eq, drift, pk_eq, pk_ne, (unsigned long)node.transmissions);
    if (!ok || samples == 0) return 2;
    if (sizeof(etobs_real) == sizeof(double)) return (dec_ne || pk_ne || eta_eq != samples) ? 1 : 0;
    return (bad || pk_ne) ? 1 : 0;
}
