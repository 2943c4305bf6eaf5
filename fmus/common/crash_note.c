/* twin's note on a fatal signal: one line on stderr before the process dies of it.
 *
 * Not part of any FMU. An FMU run in twin's own process (drive.isolation: none) that dereferences a
 * bad pointer or aborts takes the process with it; Python cannot catch that. `twin simulate` gives
 * this file the line to write (naming the FMU, the fix and the bag to recover); on SIGSEGV, SIGBUS,
 * SIGILL, SIGFPE or SIGABRT the handler writes it (write(2) only: async-signal-safe), puts back the
 * handler that was there before (Python's faulthandler's, or the default) and raises the signal again,
 * so the process still dies of it with the same status.
 */
#define _XOPEN_SOURCE 700
#include <signal.h>
#include <string.h>
#include <unistd.h>

#define TWIN_NOTE_MAX 2048

static char note[TWIN_NOTE_MAX];
static size_t note_length;
static const int fatal[] = {SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT};
#define N_FATAL (sizeof fatal / sizeof fatal[0])
static struct sigaction previous[N_FATAL];
static int installed;
/* A stack of the handler's own: an FMU that overflows its stack leaves none for the handler. */
static char alternate[64 * 1024];

static void on_fatal(int sig) {
    char number[4] = {0};
    int n = sig, k = 0;
    char digits[4];
    do {
        digits[k++] = (char)('0' + n % 10);
        n /= 10;
    } while (n > 0 && k < 3);
    for (int j = 0; j < k; j++) number[j] = digits[k - 1 - j];
    ssize_t ignored = write(STDERR_FILENO, note, note_length);
    ignored = write(STDERR_FILENO, " (signal ", 9);
    ignored = write(STDERR_FILENO, number, (size_t)k);
    ignored = write(STDERR_FILENO, ")\n", 2);
    (void)ignored;
    for (size_t i = 0; i < N_FATAL; i++) {
        if (fatal[i] == sig) sigaction(sig, &previous[i], NULL);
    }
    raise(sig);
}

/* Set the line (without its newline) and install the handler once; an empty line removes it. */
int twin_crash_note(const char *line) {
    size_t length = strlen(line);
    if (length >= TWIN_NOTE_MAX) length = TWIN_NOTE_MAX - 1;
    memcpy(note, line, length);
    note[length] = '\0';
    note_length = length;
    if (length == 0) {
        if (installed) {
            for (size_t i = 0; i < N_FATAL; i++) sigaction(fatal[i], &previous[i], NULL);
            installed = 0;
        }
        return 0;
    }
    if (installed) return 0;
    stack_t current;
    if (sigaltstack(NULL, &current) == 0 && (current.ss_flags & SS_DISABLE)) {
        stack_t own;
        memset(&own, 0, sizeof own);
        own.ss_sp = alternate;
        own.ss_size = sizeof alternate;
        sigaltstack(&own, NULL); /* (faulthandler's, when Python has one, is kept) */
    }
    struct sigaction action;
    memset(&action, 0, sizeof action);
    action.sa_handler = on_fatal;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESETHAND | SA_ONSTACK;
    for (size_t i = 0; i < N_FATAL; i++) {
        if (sigaction(fatal[i], &action, &previous[i]) != 0) return -1;
    }
    installed = 1;
    return 0;
}
