/* A host harness around the generated node (POSIX): replay the samples of a vector file in
 * real time and send the node's packets by UDP, as a sensor would (etobs).
 *
 *   etobs_host VECTORS HOST PORT TIME_SCALE
 *
 * Sample k is taken at the wall time session + t_k / TIME_SCALE, the session (the
 * deployment's epoch, a time.time() value) read from the vector file, whose samples the
 * node reads in place of a sensor. Prints "host: samples=.. transmissions=.." at the end. */
#define _POSIX_C_SOURCE 200809L
#include <arpa/inet.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "etobs_node.h"

static int sock = -1;
static struct sockaddr_in to;

static int udp_send(void *ctx, const uint8_t *data, size_t len) {
    (void)ctx;
    return sendto(sock, data, len, 0, (struct sockaddr *)&to, sizeof to) == (ssize_t)len ? 0 : -1;
}

static int store(void *ctx, uint64_t bound) {
    (void)ctx;
    (void)bound;
    return 0;
}

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int hexbyte(const char *s) {
    int v = 0, i;
    for (i = 0; i < 2; i++) {
        char c = s[i];
        v = v * 16 + (c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : c - 'A' + 10);
    }
    return v;
}

static char line[16384];

int main(int argc, char **argv) {
    FILE *f;
    etobs_node node;
    etobs_io io;
    uint8_t key[32];
    double session = 0, scale;
    long samples = 0;
    int i, ready = 0;
    if (argc != 5) {
        fprintf(stderr, "usage: etobs_host VECTORS HOST PORT TIME_SCALE\n");
        return 2;
    }
    scale = strtod(argv[4], NULL);
    memset(&to, 0, sizeof to);
    to.sin_family = AF_INET;
    to.sin_port = htons((uint16_t)atoi(argv[3]));
    if (inet_pton(AF_INET, argv[2], &to.sin_addr) != 1 || scale <= 0) {
        fprintf(stderr, "etobs_host: bad address %s or time scale %s\n", argv[2], argv[4]);
        return 2;
    }
    sock = socket(AF_INET, SOCK_DGRAM, 0);
    f = fopen(argv[1], "r");
    if (sock < 0 || f == NULL) {
        fprintf(stderr, "etobs_host: cannot open the socket or %s\n", argv[1]);
        return 2;
    }
    memset(&io, 0, sizeof io);
    io.send = udp_send;
    io.store_bound = store;
    while (fgets(line, sizeof line, f) != NULL) {
        char *tok = strtok(line, " \n");
        if (tok == NULL || tok[0] == '#') continue;
        if (strcmp(tok, "node") == 0) {
            const char *hex;
            for (i = 0; i < 3; i++) strtok(NULL, " \n");
            strtok(NULL, " \n");
            session = strtod(strtok(NULL, " \n"), NULL);
            strtok(NULL, " \n");
            hex = strtok(NULL, " \n");
            for (i = 0; i < 32; i++) key[i] = (uint8_t)hexbyte(hex + 2 * i);
            if (etobs_node_init(&node, &io, key, session, 0, 0) != 0) return 2;
            ready = 1;
        } else if (strcmp(tok, "sample") == 0 && ready) {
            double y[ETOBS_N_VALUES], due, wait;
            uint64_t k = strtoull(strtok(NULL, " \n"), NULL, 10);
            for (i = 0; i < (int)ETOBS_N_VALUES; i++) y[i] = strtod(strtok(NULL, " \n"), NULL);
            due = session + (double)k * ETOBS_PERIOD / scale;
            wait = due - now();
            if (wait > 0) {
                struct timespec ts;
                ts.tv_sec = (time_t)wait;
                ts.tv_nsec = (long)((wait - (double)ts.tv_sec) * 1e9);
                nanosleep(&ts, NULL);
            }
            if (etobs_node_sample(&node, k, y) < 0) {
                fprintf(stderr, "etobs_host: sample %llu failed\n", (unsigned long long)k);
                return 1;
            }
            samples++;
        }
    }
    fclose(f);
    close(sock);
    printf("host: samples=%ld transmissions=%lu\n", samples, (unsigned long)node.transmissions);
    return ready ? 0 : 2;
}
