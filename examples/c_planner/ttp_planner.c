/*
 * A path planner in C that drives a Teleworkbench robot with nothing but a socket.
 *
 * It "plans" by densifying the waypoints given on the command line into points at most 0.1 m
 * apart, each facing the next (the last faces along the final segment), sends the path as one
 * T,T,P line (millimetres and degrees, protocol v1), prints the agent's reply and then every
 * event until EV,DONE or EV,FAIL.
 *
 *   cc -O2 -Wall -o ttp_planner ttp_planner.c -lm
 *   ./ttp_planner 127.0.0.1 5555  0.1 0.1  0.5 0.1  0.5 0.6        (x y pairs in metres)
 *
 * Exit status: 0 DONE, 1 FAIL or ERR reply, 2 usage or connection error.
 */
#include <math.h>
#include <netdb.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#define MAX_POINTS 10000
#define SPACING_M 0.1

static int read_line(int fd, char *buf, size_t size) {
    size_t n = 0;
    char c;
    while (n + 1 < size) {
        ssize_t r = recv(fd, &c, 1, 0);
        if (r <= 0) return -1;
        if (c == '\n') break;
        if (c != '\r') buf[n++] = c;
    }
    buf[n] = '\0';
    return (int)n;
}

static int connect_to(const char *host, const char *port) {
    struct addrinfo hints = {0}, *res, *p;
    int fd = -1;
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    if (getaddrinfo(host, port, &hints, &res) != 0) return -1;
    for (p = res; p; p = p->ai_next) {
        fd = socket(p->ai_family, p->ai_socktype, p->ai_protocol);
        if (fd < 0) continue;
        if (connect(fd, p->ai_addr, p->ai_addrlen) == 0) break;
        close(fd);
        fd = -1;
    }
    freeaddrinfo(res);
    return fd;
}

int main(int argc, char **argv) {
    if (argc < 7 || (argc - 3) % 2 != 0) {
        fprintf(stderr, "usage: %s HOST PORT X1 Y1 X2 Y2 [X Y ...]   (waypoints in metres)\n", argv[0]);
        return 2;
    }
    int nw = (argc - 3) / 2;
    double *wx = malloc(sizeof(double) * nw), *wy = malloc(sizeof(double) * nw);
    for (int i = 0; i < nw; i++) {
        wx[i] = atof(argv[3 + 2 * i]);
        wy[i] = atof(argv[4 + 2 * i]);
    }

    /* the "planning": densify the polyline, headings facing the next point */
    static double px[MAX_POINTS], py[MAX_POINTS], pa[MAX_POINTS];
    int n = 0;
    px[n] = wx[0]; py[n] = wy[0]; n++;
    for (int i = 1; i < nw && n < MAX_POINTS; i++) {
        double dx = wx[i] - wx[i - 1], dy = wy[i] - wy[i - 1];
        int steps = (int)ceil(hypot(dx, dy) / SPACING_M);
        for (int k = 1; k <= steps && n < MAX_POINTS; k++) {
            px[n] = wx[i - 1] + dx * k / steps;
            py[n] = wy[i - 1] + dy * k / steps;
            n++;
        }
    }
    for (int i = 0; i < n; i++) {
        int j = i + 1 < n ? i + 1 : i, h = i + 1 < n ? i : i - 1;
        pa[i] = atan2(py[j] - py[h], px[j] - px[h]) * 180.0 / M_PI;
    }

    int fd = connect_to(argv[1], argv[2]);
    if (fd < 0) {
        fprintf(stderr, "cannot connect to %s:%s\n", argv[1], argv[2]);
        return 2;
    }
    char line[4096];
    if (read_line(fd, line, sizeof line) < 0 || strncmp(line, "HELLO,", 6) != 0) {
        fprintf(stderr, "no HELLO greeting\n");
        return 2;
    }
    printf("%s\n", line);

    size_t cap = (size_t)n * 64 + 16, len = 0;
    char *msg = malloc(cap);
    len += snprintf(msg + len, cap - len, "T,T,P,");
    for (int i = 0; i < n; i++)
        len += snprintf(msg + len, cap - len, "%s%.1f,%.1f,%.2f", i ? ";" : "", px[i] * 1000.0, py[i] * 1000.0, pa[i]);
    len += snprintf(msg + len, cap - len, "\n");
    if (send(fd, msg, len, 0) != (ssize_t)len) {
        fprintf(stderr, "send failed\n");
        return 2;
    }
    printf("sent %d points\n", n);

    int status = 1;
    while (read_line(fd, line, sizeof line) >= 0) {
        printf("%s\n", line);
        fflush(stdout);
        if (strncmp(line, "ERR,", 4) == 0) break;
        if (strncmp(line, "EV,DONE,", 8) == 0) { status = 0; break; }
        if (strncmp(line, "EV,FAIL,", 8) == 0) break;
    }
    close(fd);
    free(msg);
    free(wx);
    free(wy);
    return status;
}
