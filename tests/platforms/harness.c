/* FMI 3.0 Co-Simulation harness for the platform test (issue 17): loads the FMU's library,
 * runs the schedule read from standard input and prints every recorded output at every
 * step, f64 as the hex of its bits, so that runs on different platforms compare bit for bit.
 * Built with gcc (x86_64 Linux), x86_64-w64-mingw32-gcc (run under Wine) and
 * aarch64-linux-gnu-gcc (run under qemu-user). Usage: harness LIBRARY < schedule > trace
 *
 * Schedule, one command per line (floats as the 16 hex digits of their IEEE-754 bits):
 *   T token            instantiate (Co-Simulation); forgets the outputs an O declared
 *   F vr bits          fmi3SetFloat64 of one value
 *   I vr value         fmi3SetInt32 of one value
 *   B vr 0|1           fmi3SetBoolean of one value
 *   E start stop       fmi3EnterInitializationMode with a stop time
 *   X                  fmi3ExitInitializationMode
 *   O kind n vr...     the outputs to record (kind f, i or b), in the order to print them
 *   R                  print one line: the outputs as declared by O, in the order declared
 *   S t h              fmi3DoStep(t, h)
 *   Q                  fmi3Terminate and fmi3FreeInstance
 * Any status other than OK stops the run with exit code 1. */
#include <stdarg.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef _WIN32
#include <windows.h>
#else
#include <dlfcn.h>
#endif

typedef void *Inst;
typedef int Status; /* fmi3Status: 0 OK */
typedef void (*Logger)(void *env, int status, const char *category, const char *message);
typedef Inst (*InstantiateCS)(const char *, const char *, const char *, bool, bool, bool, bool,
                              const uint32_t *, size_t, void *, Logger, void *);
typedef Status (*EnterInit)(Inst, bool, double, double, bool, double);
typedef Status (*Simple)(Inst);
typedef Status (*SetF64)(Inst, const uint32_t *, size_t, const double *, size_t);
typedef Status (*SetI32)(Inst, const uint32_t *, size_t, const int32_t *, size_t);
typedef Status (*SetBool)(Inst, const uint32_t *, size_t, const bool *, size_t);
typedef Status (*GetF64)(Inst, const uint32_t *, size_t, double *, size_t);
typedef Status (*GetI32)(Inst, const uint32_t *, size_t, int32_t *, size_t);
typedef Status (*GetBool)(Inst, const uint32_t *, size_t, bool *, size_t);
typedef Status (*DoStep)(Inst, double, double, bool, bool *, bool *, bool *, double *);
typedef void (*FreeInst)(Inst);

static void *library;

static void *symbol(const char *name) {
#ifdef _WIN32
    void *f = (void *)GetProcAddress((HMODULE)library, name);
#else
    void *f = dlsym(library, name);
#endif
    if (!f) {
        fprintf(stderr, "harness: %s not exported\n", name);
        exit(2);
    }
    return f;
}

static void logger(void *env, int status, const char *category, const char *message) {
    (void)env;
    fprintf(stderr, "fmu [%d %s] %s\n", status, category ? category : "", message ? message : "");
}

static double from_bits(const char *hex) {
    uint64_t u = strtoull(hex, NULL, 16);
    double d;
    memcpy(&d, &u, sizeof d);
    return d;
}

static void check(Status s, const char *what, long line) {
    if (s != 0) {
        fprintf(stderr, "harness: %s returned status %d (schedule line %ld)\n", what, s, line);
        exit(1);
    }
}

#define MAX_OUT 256

int main(int argc, char **argv) {
    if (argc != 2) {
        fprintf(stderr, "usage: harness LIBRARY < schedule\n");
        return 2;
    }
#ifdef _WIN32
    library = (void *)LoadLibraryA(argv[1]);
    if (!library) {
        fprintf(stderr, "harness: LoadLibrary(%s) failed: error %lu\n", argv[1], (unsigned long)GetLastError());
        return 2;
    }
#else
    library = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!library) {
        fprintf(stderr, "harness: %s\n", dlerror());
        return 2;
    }
#endif
    InstantiateCS instantiate = (InstantiateCS)symbol("fmi3InstantiateCoSimulation");
    EnterInit enter = (EnterInit)symbol("fmi3EnterInitializationMode");
    Simple exit_init = (Simple)symbol("fmi3ExitInitializationMode");
    Simple terminate = (Simple)symbol("fmi3Terminate");
    FreeInst free_instance = (FreeInst)symbol("fmi3FreeInstance");
    SetF64 set_f64 = (SetF64)symbol("fmi3SetFloat64");
    SetI32 set_i32 = (SetI32)symbol("fmi3SetInt32");
    SetBool set_bool = (SetBool)symbol("fmi3SetBoolean");
    GetF64 get_f64 = (GetF64)symbol("fmi3GetFloat64");
    GetI32 get_i32 = (GetI32)symbol("fmi3GetInt32");
    GetBool get_bool = (GetBool)symbol("fmi3GetBoolean");
    DoStep do_step = (DoStep)symbol("fmi3DoStep");

    Inst inst = NULL;
    /* Recorded outputs: kind and value reference in print order. */
    char kinds[MAX_OUT];
    uint32_t vrs[MAX_OUT];
    size_t n_out = 0;
    static char line[1 << 16];
    long line_no = 0;
    static char out[MAX_OUT * 20 + 2];
    while (fgets(line, sizeof line, stdin)) {
        line_no++;
        char *save = NULL;
        char *cmd = strtok_r(line, " \r\n", &save);
        if (!cmd) continue;
        char *a = strtok_r(NULL, " \r\n", &save);
        char *b = strtok_r(NULL, " \r\n", &save);
        switch (cmd[0]) {
        case 'T':
            n_out = 0;
            inst = instantiate("harness", a, NULL, false, false, false, false, NULL, 0, NULL, logger, NULL);
            if (!inst) {
                fprintf(stderr, "harness: instantiation failed\n");
                return 1;
            }
            break;
        case 'F': {
            uint32_t vr = (uint32_t)strtoul(a, NULL, 10);
            double v = from_bits(b);
            check(set_f64(inst, &vr, 1, &v, 1), "fmi3SetFloat64", line_no);
            break;
        }
        case 'I': {
            uint32_t vr = (uint32_t)strtoul(a, NULL, 10);
            int32_t v = (int32_t)strtol(b, NULL, 10);
            check(set_i32(inst, &vr, 1, &v, 1), "fmi3SetInt32", line_no);
            break;
        }
        case 'B': {
            uint32_t vr = (uint32_t)strtoul(a, NULL, 10);
            bool v = strcmp(b, "0") != 0;
            check(set_bool(inst, &vr, 1, &v, 1), "fmi3SetBoolean", line_no);
            break;
        }
        case 'E':
            check(enter(inst, false, 0.0, from_bits(a), true, from_bits(b)), "fmi3EnterInitializationMode", line_no);
            break;
        case 'X':
            check(exit_init(inst), "fmi3ExitInitializationMode", line_no);
            break;
        case 'O': {
            long n = strtol(b, NULL, 10);
            for (long k = 0; k < n; k++) {
                char *v = strtok_r(NULL, " \r\n", &save);
                if (!v || n_out >= MAX_OUT) {
                    fprintf(stderr, "harness: bad O line %ld\n", line_no);
                    return 2;
                }
                kinds[n_out] = a[0];
                vrs[n_out++] = (uint32_t)strtoul(v, NULL, 10);
            }
            break;
        }
        case 'R': {
            size_t pos = 0;
            for (size_t k = 0; k < n_out; k++) {
                if (kinds[k] == 'f') {
                    double d;
                    check(get_f64(inst, &vrs[k], 1, &d, 1), "fmi3GetFloat64", line_no);
                    uint64_t u;
                    memcpy(&u, &d, sizeof u);
                    pos += (size_t)sprintf(out + pos, "%s%016llx", k ? " " : "", (unsigned long long)u);
                } else if (kinds[k] == 'i') {
                    int32_t i;
                    check(get_i32(inst, &vrs[k], 1, &i, 1), "fmi3GetInt32", line_no);
                    pos += (size_t)sprintf(out + pos, "%s%ld", k ? " " : "", (long)i);
                } else {
                    bool v;
                    check(get_bool(inst, &vrs[k], 1, &v, 1), "fmi3GetBoolean", line_no);
                    pos += (size_t)sprintf(out + pos, "%s%d", k ? " " : "", v ? 1 : 0);
                }
            }
            out[pos++] = '\n';
            fwrite(out, 1, pos, stdout);
            break;
        }
        case 'S': {
            bool event = false, term = false, early = false;
            double last = 0.0;
            check(do_step(inst, from_bits(a), from_bits(b), true, &event, &term, &early, &last), "fmi3DoStep", line_no);
            break;
        }
        case 'Q':
            check(terminate(inst), "fmi3Terminate", line_no);
            free_instance(inst);
            inst = NULL;
            break;
        default:
            fprintf(stderr, "harness: unknown command %s on line %ld\n", cmd, line_no);
            return 2;
        }
    }
    fflush(stdout);
    return 0;
}
