/* A one-thread pool that stops its thread before a fork as ducc0's and pocketfft's pools do:
 * a pthread_atfork prepare handler sets a flag and wakes the thread without taking the mutex
 * the thread waits under, then joins it; the parent and child handlers start a fresh thread.
 * The thread checks the flag, then runs for SPIN_S seconds before its first wait: a stop in
 * that window is missed, and the fork waits for the thread for ever.  The window is widened
 * from the libraries' few instructions so that a test can hit it every time.
 *
 * Build: cc -O2 -shared -fPIC -o liblost_wakeup_pool.so lost_wakeup_pool.c -lpthread
 * Use:   pool_start() once; each fork after it then runs the handlers. */
#include <pthread.h>
#include <stdatomic.h>
#include <time.h>

#define SPIN_S 0.2

static pthread_mutex_t mut = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t wake = PTHREAD_COND_INITIALIZER;
static atomic_int stopping;
static pthread_t thread;

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static void *work(void *arg) {
    (void)arg;
    int first = 1;
    pthread_mutex_lock(&mut);
    while (!atomic_load(&stopping)) {
        if (first) { /* checked, not yet waiting: the window, held open while running */
            double end = now() + SPIN_S;
            while (now() < end) {}
            first = 0;
        }
        pthread_cond_wait(&wake, &mut);
    }
    pthread_mutex_unlock(&mut);
    return 0;
}

static void start(void) {
    atomic_store(&stopping, 0);
    pthread_create(&thread, 0, work, 0);
}

static void stop(void) {
    atomic_store(&stopping, 1);
    pthread_cond_broadcast(&wake); /* without the mutex: a thread in the window misses it */
    pthread_join(thread, 0);
}

int pool_start(void) {
    start();
    return pthread_atfork(stop, start, start);
}
