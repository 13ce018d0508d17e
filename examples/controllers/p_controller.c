/* An uploaded Teleworkbench controller in C (stdlib + sockets): a P-controller on the PO stream along the
 * planned path's waypoints, like p_controller.py.
 *
 * Build: cc -O2 -static -o p_controller p_controller.c -lm; upload with "kind": "executable".
 * Inputs: TWB_ROBOT_HOST, TWB_ROBOT_PORT, TWB_PATH_FILE ({"path": [[x, y, theta], ...]}, m, m, rad).
 * Lines out: T,T,O,1 once, then T,T,V,<mm/s>,<deg/s> for every PO line; T,T,V,0,0 within 2 cm of the goal.
 */
#include <arpa/inet.h>
#include <ctype.h>
#include <math.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#define MAX_POINTS 10000
#define V_MAX 150.0   /* mm/s */
#define W_MAX 2.5     /* rad/s */
#define K_V 1500.0    /* (mm/s)/m */
#define K_W 4.0       /* 1/s */
#define SWITCH_M 0.05
#define STOP_M 0.02

static double px[MAX_POINTS], py[MAX_POINTS];

/* The path's points: every number of the file after "path", three per point. */
static int read_path(const char *file) {
    FILE *f = fopen(file, "r");
    if (!f) { perror(file); exit(2); }
    static char text[1 << 20];
    size_t len = fread(text, 1, sizeof text - 1, f);
    fclose(f);
    text[len] = 0;
    char *s = strstr(text, "\"path\"");
    if (!s) { fprintf(stderr, "no path in %s\n", file); exit(2); }
    s += 6;
    int k = 0, n = 0;
    while (*s && n < MAX_POINTS) {
        if (*s == '-' || isdigit((unsigned char)*s)) {
            char *end;
            double v = strtod(s, &end);
            if (k % 3 == 0) px[n] = v; else if (k % 3 == 1) py[n] = v; else n++;
            k++;
            s = end;
        } else {
            s++;
        }
    }
    return n;
}

static void say(int fd, const char *line) {
    size_t len = strlen(line);
    while (len > 0) {
        ssize_t w = write(fd, line, len);
        if (w <= 0) exit(1);
        line += w;
        len -= (size_t)w;
    }
}

int main(void) {
    const char *host = getenv("TWB_ROBOT_HOST"), *port = getenv("TWB_ROBOT_PORT"), *file = getenv("TWB_PATH_FILE");
    if (!host || !port || !file) { fprintf(stderr, "TWB_ROBOT_HOST, TWB_ROBOT_PORT and TWB_PATH_FILE needed\n"); return 2; }
    int n = read_path(file);
    if (n < 2) { fprintf(stderr, "the path has %d points\n", n); return 2; }
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    struct sockaddr_in addr = {.sin_family = AF_INET, .sin_port = htons((unsigned short)atoi(port))};
    inet_pton(AF_INET, host, &addr.sin_addr);
    if (connect(fd, (struct sockaddr *)&addr, sizeof addr) != 0) { perror("connect"); return 1; }
    FILE *in = fdopen(fd, "r");
    char line[4096], out[128];
    if (!fgets(line, sizeof line, in)) return 1;
    printf("robot: %s", line);
    say(fd, "T,T,O,1\n");
    int k = 1;
    while (fgets(line, sizeof line, in)) {
        if (!strncmp(line, "EV,FAIL", 7) || !strncmp(line, "ERR", 3)) {
            printf("robot: %s", line);
            /* the run is over: stopped at the goal, or a T,T,V sent after its end (ERR,STATE) */
            return strncmp(line, "EV,FAIL,STOPPED", 15) == 0 || strncmp(line, "ERR,STATE", 9) == 0 ? 0 : 1;
        }
        double xm, ym, adeg, t;
        if (sscanf(line, "PO,%lf,%lf,%lf,%lf", &xm, &ym, &adeg, &t) != 4) continue;
        double x = xm / 1000.0, y = ym / 1000.0, th = adeg * M_PI / 180.0;
        while (k < n - 1 && hypot(px[k] - x, py[k] - y) < SWITCH_M) k++;
        double d = hypot(px[k] - x, py[k] - y);
        if (k == n - 1 && d < STOP_M) {
            say(fd, "T,T,V,0,0\n");  /* at the goal: stand (the testbed then ends the run) */
            continue;
        }
        double err = remainder(atan2(py[k] - y, px[k] - x) - th, 2 * M_PI);
        double v = fmin(V_MAX, K_V * d) * fmax(cos(err), 0.0);
        double w = fmax(-W_MAX, fmin(W_MAX, K_W * err));
        snprintf(out, sizeof out, "T,T,V,%.1f,%.1f\n", v, w * 180.0 / M_PI);
        say(fd, out);
    }
    printf("the robot port closed\n");
    return 0;
}
