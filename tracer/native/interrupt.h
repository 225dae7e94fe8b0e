/* Hearing SIGINT and SIGTERM while C code runs (tracer/signals.py is the Python side).
 *
 * Python runs its signal handlers only in the main thread, between bytecodes: a signal that arrives while the
 * main thread is inside a long C call (a ray tree, a BVH build, usd-core writing a file with the GIL held)
 * is not acted on until that call returns.  rt_interrupt_install() puts a C handler in front of Python's:
 *
 *  - it records the signal (rt_interrupt_heard), which the ray tracer polls at every ray, so that a batch
 *    stops within microseconds and Python's handler then runs;
 *  - it calls Python's own handler, which asks the interpreter to run the Python-level one;
 *  - it wakes a watchdog thread: if the process is still alive `grace` milliseconds later (stuck in a call
 *    that polls nothing), the watchdog removes the temporary files registered with rt_interrupt_hold_file
 *    (an atomic write's named temporary: the user's old file is never touched) and ends the process with
 *    status 128 + the signal, as the shell reports a process a signal ended.
 *
 * rt_interrupt_disarm() stops the watchdog from acting (the program has finished its work: a late signal
 * changes nothing), rt_interrupt_uninstall() gives Python its handler back.  Not on Windows (no sigaction):
 * there install reports failure and only Python's own handling remains. */
#ifndef RT_INTERRUPT_H
#define RT_INTERRUPT_H

#include <stdatomic.h>
#include <stdint.h>

/* The signal heard since the last rt_interrupt_clear(), or 0. */
static _Atomic int rt_heard_signal;

int rt_interrupt_heard(void) { return atomic_load_explicit(&rt_heard_signal, memory_order_relaxed); }

void rt_interrupt_clear(void) { atomic_store(&rt_heard_signal, 0); }

#ifndef _WIN32
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <semaphore.h>
#include <signal.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#define RT_HELD_FILES 16
#define RT_HELD_PATH 4096

static struct sigaction rt_python_action[2];  /* [0]: SIGINT, [1]: SIGTERM, as they were before install */
static _Atomic int rt_installed, rt_armed, rt_watchdog_running;
static _Atomic int64_t rt_grace_ms;
static sem_t rt_wake;
static char rt_held_path[RT_HELD_FILES][RT_HELD_PATH];
static _Atomic int rt_held_used[RT_HELD_FILES];
/* The program's standard error as it was at install: while a library's messages are held back (fd 2 pointed at
 * a temporary file, tracer/diagnostics.py), the watchdog's line must still reach the user. */
static _Atomic int rt_stderr_fd = -1;

static void rt_on_signal(int sig)
{
    int saved = errno;
    atomic_store(&rt_heard_signal, sig);
    const struct sigaction *python = &rt_python_action[sig == SIGTERM];
    if (python->sa_flags & SA_SIGINFO) {
        if (python->sa_sigaction)
            python->sa_sigaction(sig, NULL, NULL);
    } else if (python->sa_handler != SIG_DFL && python->sa_handler != SIG_IGN && python->sa_handler) {
        python->sa_handler(sig);
    }
    if (atomic_load(&rt_armed))
        sem_post(&rt_wake);  /* (async-signal-safe) */
    errno = saved;
}

static void *rt_watchdog(void *unused)
{
    (void)unused;
    for (;;) {
        while (sem_wait(&rt_wake) != 0) {
        }
        if (!atomic_load(&rt_armed))
            continue;
        int64_t ms = atomic_load(&rt_grace_ms);
        struct timespec left = {(time_t)(ms / 1000), (long)(ms % 1000) * 1000000L};
        while (nanosleep(&left, &left) != 0 && errno == EINTR) {
        }
        if (!atomic_load(&rt_armed))
            continue;
        for (int k = 0; k < RT_HELD_FILES; k++)
            if (atomic_load(&rt_held_used[k]) == 1)
                unlink(rt_held_path[k]);
        static const char said[] = "\ninterrupted\n";
        int fd = atomic_load(&rt_stderr_fd);
        ssize_t ignored = write(fd >= 0 ? fd : 2, said, sizeof(said) - 1);
        (void)ignored;
        _exit(128 + atomic_load(&rt_heard_signal));
    }
    return NULL;
}

/* Put the C handler in front of the current (Python's) handlers of SIGINT and SIGTERM and arm the watchdog
 * with `grace_ms`.  0 on success, -1 when a handler or the thread could not be set up. */
int rt_interrupt_install(int64_t grace_ms)
{
    atomic_store(&rt_grace_ms, grace_ms);
    int old_fd = atomic_exchange(&rt_stderr_fd, fcntl(2, F_DUPFD_CLOEXEC, 3));
    if (old_fd >= 0)
        close(old_fd);
    if (!atomic_load(&rt_watchdog_running)) {
        if (sem_init(&rt_wake, 0, 0) != 0)
            return -1;
        sigset_t all, before;
        sigfillset(&all);
        pthread_sigmask(SIG_BLOCK, &all, &before);  /* the watchdog inherits a mask that blocks every signal */
        pthread_t thread;
        pthread_attr_t attr;
        pthread_attr_init(&attr);
        pthread_attr_setdetachstate(&attr, PTHREAD_CREATE_DETACHED);
        int failed = pthread_create(&thread, &attr, rt_watchdog, NULL);
        pthread_attr_destroy(&attr);
        pthread_sigmask(SIG_SETMASK, &before, NULL);
        if (failed)
            return -1;
        atomic_store(&rt_watchdog_running, 1);
    }
    if (!atomic_load(&rt_installed)) {
        if (sigaction(SIGINT, NULL, &rt_python_action[0]) != 0 || sigaction(SIGTERM, NULL, &rt_python_action[1]) != 0)
            return -1;
        struct sigaction ours;
        memset(&ours, 0, sizeof(ours));
        ours.sa_handler = rt_on_signal;
        sigemptyset(&ours.sa_mask);
        ours.sa_flags = rt_python_action[0].sa_flags & ~SA_SIGINFO;  /* (Python's: SA_ONSTACK) */
        /* (a signal the process ignores, as a shell's `cmd &` makes SIGINT, stays ignored) */
        int failed = 0;
        if (rt_python_action[0].sa_handler != SIG_IGN)
            failed |= sigaction(SIGINT, &ours, NULL) != 0;
        if (rt_python_action[1].sa_handler != SIG_IGN)
            failed |= sigaction(SIGTERM, &ours, NULL) != 0;
        if (failed) {
            sigaction(SIGINT, &rt_python_action[0], NULL);
            sigaction(SIGTERM, &rt_python_action[1], NULL);
            return -1;
        }
        atomic_store(&rt_installed, 1);
    }
    atomic_store(&rt_armed, 1);
    return 0;
}

/* The watchdog no longer acts on signals (they are still recorded and passed on to Python). */
void rt_interrupt_disarm(void) { atomic_store(&rt_armed, 0); }

/* Python's handlers back, the watchdog disarmed. */
void rt_interrupt_uninstall(void)
{
    atomic_store(&rt_armed, 0);
    if (atomic_exchange(&rt_installed, 0)) {
        sigaction(SIGINT, &rt_python_action[0], NULL);
        sigaction(SIGTERM, &rt_python_action[1], NULL);
    }
}

/* Remember a file for the watchdog to remove; its slot (for rt_interrupt_release_file), or -1 when the table
 * is full or the path too long (the file is then not removed by the watchdog). */
int rt_interrupt_hold_file(const char *path)
{
    size_t length = strlen(path);
    if (length >= RT_HELD_PATH)
        return -1;
    for (int k = 0; k < RT_HELD_FILES; k++) {
        int expected = 0;
        if (atomic_load(&rt_held_used[k]) == 0 && atomic_compare_exchange_strong(&rt_held_used[k], &expected, 2)) {
            memcpy(rt_held_path[k], path, length + 1);
            atomic_store(&rt_held_used[k], 1);
            return k;
        }
    }
    return -1;
}

void rt_interrupt_release_file(int slot)
{
    if (slot >= 0 && slot < RT_HELD_FILES)
        atomic_store(&rt_held_used[slot], 0);
}

#else /* _WIN32 */

int rt_interrupt_install(int64_t grace_ms)
{
    (void)grace_ms;
    return -1;
}
void rt_interrupt_disarm(void) {}
void rt_interrupt_uninstall(void) {}
int rt_interrupt_hold_file(const char *path)
{
    (void)path;
    return -1;
}
void rt_interrupt_release_file(int slot) { (void)slot; }

#endif
#endif
