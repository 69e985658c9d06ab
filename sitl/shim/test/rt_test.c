/*
 * drivecheck SITL shim: tests of the kernel subset (sitl_rt.c) without any firmware. Run by the
 * crate's unit tests: `rt_test` runs them all and prints `ok`; `rt_test deadlock` must end in
 * sitl_fatal (exit 3).
 */
#include "sitl.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

_Noreturn void sitl_fatal(const char *msg) {
  printf("fatal: %s\n", msg);
  fflush(stdout);
  exit(3);
}

static int failures;
#define CHECK(c)                                                   \
  do {                                                             \
    if (!(c)) {                                                    \
      printf("%s:%d: check failed: %s\n", __FILE__, __LINE__, #c); \
      failures++;                                                  \
    }                                                              \
  } while (0)

/* an event log: "<name>@<us>" entries */
static char log_buf[4096];
static void note(const char *name) {
  char e[64];
  snprintf(e, sizeof e, "%s@%llu ", name, (unsigned long long)sitl_rt_now_us());
  strncat(log_buf, e, sizeof log_buf - strlen(log_buf) - 1);
}

static uint8_t wa[16];

/* ---- sleeping: wake order by deadline, then FIFO ---- */
static THD_FUNCTION(sleeper, arg) {
  const char *name = arg;
  chThdSleepMilliseconds(name[0] == 'a' ? 3 : 2);
  note(name);
  chThdSleepMilliseconds(1);
  note(name);
}

/* ---- a mutex handed over, and priority ---- */
static mutex_t mtx;
static THD_FUNCTION(holder, arg) {
  (void)arg;
  chMtxLock(&mtx);
  note("hold");
  chThdSleepMilliseconds(5);
  chMtxUnlock(&mtx); /* the waiter has a higher priority: it runs before the next line */
  note("released");
}
static THD_FUNCTION(waiter, arg) {
  (void)arg;
  chThdSleepMilliseconds(1);
  note("want");
  chMtxLock(&mtx);
  note("got");
  chMtxUnlock(&mtx);
}

/* ---- virtual timers ---- */
static virtual_timer_t vt1, vt2;
static void vt_cb(void *p) { note((const char *)p); }

/* ---- events with a timeout ---- */
static thread_t *evt_tp;
static eventmask_t evt_got[2];
static THD_FUNCTION(evt_waiter, arg) {
  (void)arg;
  evt_got[0] = chEvtWaitAnyTimeout(ALL_EVENTS, MS2ST(2)); /* nobody signals: times out */
  note("evt-timeout");
  evt_got[1] = chEvtWaitAnyTimeout(ALL_EVENTS, MS2ST(50));
  note("evt");
}
static THD_FUNCTION(evt_signaller, arg) {
  (void)arg;
  chThdSleepMilliseconds(10);
  chEvtSignal(evt_tp, (eventmask_t)4);
}

/* ---- semaphores ---- */
static semaphore_t sem;
static msg_t sem_got[2];
static THD_FUNCTION(sem_waiter, arg) {
  (void)arg;
  sem_got[0] = chSemWaitTimeout(&sem, MS2ST(1));
  sem_got[1] = chSemWaitTimeout(&sem, MS2ST(100));
  note("sem");
}
static THD_FUNCTION(sem_signaller, arg) {
  (void)arg;
  chThdSleepMilliseconds(20);
  chSemSignal(&sem);
}

/* ---- a periodic thread without drift ---- */
static uint64_t periodic_times[5];
static THD_FUNCTION(periodic, arg) {
  (void)arg;
  systime_t t = chVTGetSystemTime();
  for (int i = 0; i < 5; i++) {
    t = chThdSleepUntilWindowed(t, t + MS2ST(10));
    periodic_times[i] = sitl_rt_now_us();
  }
}

static THD_FUNCTION(self_locker, arg) {
  (void)arg;
  chMtxLock(&mtx);
  chMtxLock(&mtx);
}

int main(int argc, char **argv) {
  if (argc > 1 && strcmp(argv[1], "deadlock") == 0) {
    chMtxObjectInit(&mtx);
    chThdCreateStatic(wa, sizeof wa, NORMALPRIO, self_locker, NULL);
    sitl_rt_run_until(1000);
    printf("no deadlock reported\n");
    return 0;
  }

  /* sleeping */
  chThdCreateStatic(wa, sizeof wa, NORMALPRIO, sleeper, "a");
  chThdCreateStatic(wa, sizeof wa, NORMALPRIO, sleeper, "b");
  chThdCreateStatic(wa, sizeof wa, NORMALPRIO, sleeper, "c");
  sitl_rt_run_until(2500);
  CHECK(sitl_rt_now_us() == 2500); /* never past the target */
  CHECK(strcmp(log_buf, "b@2000 c@2000 ") == 0);
  sitl_rt_run_until(10000);
  CHECK(strcmp(log_buf, "b@2000 c@2000 a@3000 b@3000 c@3000 a@4000 ") == 0);
  printf("sleep: %s\n", log_buf);

  /* mutex */
  log_buf[0] = 0;
  chMtxObjectInit(&mtx);
  chThdCreateStatic(wa, sizeof wa, NORMALPRIO, holder, NULL);
  chThdCreateStatic(wa, sizeof wa, NORMALPRIO + 1, waiter, NULL);
  sitl_rt_run_until(20000);
  CHECK(strcmp(log_buf, "hold@10000 want@11000 got@15000 released@15000 ") == 0);
  printf("mutex: %s\n", log_buf);

  /* a delay started between ticks ends on a tick (100 us at 10 kHz) */
  log_buf[0] = 0;
  sitl_rt_run_until(20050);
  chVTObjectInit(&vt1);
  chVTObjectInit(&vt2);
  chVTSet(&vt1, MS2ST(1), vt_cb, "vt1");
  chVTSet(&vt2, MS2ST(2), vt_cb, "vt2");
  chVTReset(&vt2);
  CHECK(!chVTIsArmedI(&vt2) && chVTIsArmedI(&vt1));
  sitl_rt_run_until(30000);
  CHECK(strcmp(log_buf, "vt1@21000 ") == 0);
  printf("timers: %s\n", log_buf);

  /* events */
  log_buf[0] = 0;
  evt_tp = chThdCreateStatic(wa, sizeof wa, NORMALPRIO, evt_waiter, NULL);
  chThdCreateStatic(wa, sizeof wa, NORMALPRIO, evt_signaller, NULL);
  sitl_rt_run_until(100000);
  CHECK(evt_got[0] == 0 && evt_got[1] == 4);
  CHECK(strcmp(log_buf, "evt-timeout@32000 evt@40000 ") == 0);
  printf("events: %s\n", log_buf);

  /* semaphores */
  log_buf[0] = 0;
  chSemObjectInit(&sem, 0);
  chThdCreateStatic(wa, sizeof wa, NORMALPRIO, sem_waiter, NULL);
  chThdCreateStatic(wa, sizeof wa, NORMALPRIO, sem_signaller, NULL);
  sitl_rt_run_until(200000);
  CHECK(sem_got[0] == MSG_TIMEOUT && sem_got[1] == MSG_OK);
  CHECK(strcmp(log_buf, "sem@120000 ") == 0);
  printf("semaphores: %s\n", log_buf);

  /* periodic */
  chThdCreateStatic(wa, sizeof wa, NORMALPRIO, periodic, NULL);
  sitl_rt_run_until(300000);
  for (int i = 0; i < 5; i++) CHECK(periodic_times[i] == 200000 + 10000 * (uint64_t)(i + 1));

  /* system time in ticks */
  CHECK(chVTGetSystemTimeX() == 3000);
  CHECK(MS2ST(2) == 20 && US2ST(150) == 2 && ST2MS(25) == 3);

  if (failures) {
    printf("%d failures\n", failures);
    return 1;
  }
  printf("ok\n");
  return 0;
}
