/*
 * drivecheck SITL shim: a ChibiOS/RT 3.x API subset for running the car firmware's portable C on
 * a host, on one virtual CPU in virtual time. Written for drivecheck (MIT OR Apache-2.0); it
 * declares the API the firmware calls, it contains no ChibiOS code.
 *
 * Scheduling is cooperative and deterministic: one thread runs at a time, a thread runs until it
 * sleeps or blocks, and virtual time advances only when the host tells the executable to.
 */
#ifndef SITL_CH_H
#define SITL_CH_H

#include <stdint.h>
#include <stdbool.h>
#include <stddef.h>

#include "chtypes.h"

/* The tree's own kernel configuration (tick rate and the like), if it has one. */
#if defined(__has_include)
#if __has_include("chconf.h")
#include "chconf.h"
#endif
#endif

#ifndef CH_CFG_ST_FREQUENCY
#define CH_CFG_ST_FREQUENCY 10000
#endif

#include "chsystypes.h"

#define NOPRIO 0
#define IDLEPRIO 1
#define LOWPRIO 2
#define NORMALPRIO 128
#define HIGHPRIO 255
#define ABSPRIO 255

#define TIME_IMMEDIATE ((systime_t)0)
#define TIME_INFINITE ((systime_t)-1)

#define MSG_OK ((msg_t)0)
#define MSG_TIMEOUT ((msg_t)-1)
#define MSG_RESET ((msg_t)-2)

#define ALL_EVENTS ((eventmask_t)-1)
#define EVENT_MASK(eid) ((eventmask_t)1 << (eventmask_t)(eid))

#define CH_STATE_READY 0
#define CH_STATE_CURRENT 1
#define CH_STATE_WTSTART 2
#define CH_STATE_SUSPENDED 3
#define CH_STATE_QUEUED 4
#define CH_STATE_WTSEM 5
#define CH_STATE_WTMTX 6
#define CH_STATE_WTCOND 7
#define CH_STATE_SLEEPING 8
#define CH_STATE_WTEXIT 9
#define CH_STATE_WTOREVT 10
#define CH_STATE_WTANDEVT 11
#define CH_STATE_SNDMSGQ 12
#define CH_STATE_SNDMSG 13
#define CH_STATE_WTMSG 14
#define CH_STATE_FINAL 15
#define CH_STATE_NAMES \
  "READY", "CURRENT", "WTSTART", "SUSPENDED", "QUEUED", "WTSEM", "WTMTX", "WTCOND", "SLEEPING", \
  "WTEXIT", "WTOREVT", "WTANDEVT", "SNDMSGQ", "SNDMSG", "WTMSG", "FINAL"

/* Time conversions, rounding up to whole ticks as the kernel does. */
#define S2ST(sec) ((systime_t)((uint64_t)(sec) * CH_CFG_ST_FREQUENCY))
#define MS2ST(msec) ((systime_t)(((uint64_t)(msec) * CH_CFG_ST_FREQUENCY + 999ULL) / 1000ULL))
#define US2ST(usec) ((systime_t)(((uint64_t)(usec) * CH_CFG_ST_FREQUENCY + 999999ULL) / 1000000ULL))
#define ST2S(n) (((uint64_t)(n) + CH_CFG_ST_FREQUENCY - 1ULL) / CH_CFG_ST_FREQUENCY)
#define ST2MS(n) (((uint64_t)(n) * 1000ULL + CH_CFG_ST_FREQUENCY - 1ULL) / CH_CFG_ST_FREQUENCY)
#define ST2US(n) (((uint64_t)(n) * 1000000ULL + CH_CFG_ST_FREQUENCY - 1ULL) / CH_CFG_ST_FREQUENCY)

/* Threads. The working area only sizes nothing: each thread gets a host stack of its own. */
#define THD_WORKING_AREA(s, n) uint8_t s[(n) < 16 ? 16 : (n)]
#define THD_WORKING_AREA_SIZE(n) (n)
#define THD_FUNCTION(tname, arg) void tname(void *arg)
#define WORKING_AREA(s, n) THD_WORKING_AREA(s, n)
#define PORT_WA_SIZE(n) (n)

typedef void (*tfunc_t)(void *p);

struct sitl_thread_ctx {
  void *r13;
};

struct ch_thread {
  /* the fields the firmware's `threads` terminal command reads */
  struct sitl_thread_ctx p_ctx;
  tprio_t p_prio;
  trefs_t p_refs;
  tstate_t p_state;
  const char *p_name;
  systime_t p_time;
  /* shim private */
  struct sitl_thread_priv *priv;
  struct ch_thread *reg_next;
};

struct ch_mutex {
  thread_t *owner;
  struct sitl_waitq *waiters;
  int id;
};

struct ch_virtual_timer {
  struct ch_virtual_timer *next;
  uint64_t due_us;
  uint64_t seq;
  vtfunc_t func;
  void *par;
  bool armed;
};

struct ch_event_listener {
  struct ch_event_listener *next;
  thread_t *listener;
  eventmask_t events;
  eventflags_t flags;
  eventflags_t wflags;
};

struct ch_event_source {
  struct ch_event_listener *next;
};

struct ch_semaphore {
  cnt_t cnt;
  struct sitl_waitq *waiters;
};

struct ch_binary_semaphore {
  semaphore_t sem;
};

/* System */
void chSysInit(void);
void chSysHalt(const char *reason);
void chSysLock(void);
void chSysUnlock(void);
void chSysLockFromISR(void);
void chSysUnlockFromISR(void);
#define chSysLockFromIsr chSysLockFromISR
#define chSysUnlockFromIsr chSysUnlockFromISR
void chSchRescheduleS(void);
#define osalSysLock chSysLock
#define osalSysUnlock chSysUnlock
#define chDbgAssert(c, r) ((void)(c))
#define chDbgCheck(c) ((void)(c))
#define osalDbgAssert(c, r) ((void)(c))
#define osalDbgCheck(c) ((void)(c))

/* Threads */
thread_t *chThdCreateStatic(void *wsp, size_t size, tprio_t prio, tfunc_t pf, void *arg);
thread_t *chThdGetSelfX(void);
void chThdSleep(systime_t time);
void chThdSleepS(systime_t time);
void chThdSleepUntil(systime_t time);
systime_t chThdSleepUntilWindowed(systime_t prev, systime_t next);
void chThdYield(void);
void chThdExit(msg_t msg);
bool chThdShouldTerminateX(void);
void chThdTerminate(thread_t *tp);
tprio_t chThdSetPriority(tprio_t newprio);
tprio_t chThdGetPriorityX(void);
#define chThdSleepSeconds(sec) chThdSleep(S2ST(sec))
#define chThdSleepMilliseconds(msec) chThdSleep(MS2ST(msec))
#define chThdSleepMicroseconds(usec) chThdSleep(US2ST(usec))
#define chThdSleepS(t) chThdSleep(t)

/* Registry */
void chRegSetThreadName(const char *name);
thread_t *chRegFirstThread(void);
thread_t *chRegNextThread(thread_t *tp);

/* System time and virtual timers */
systime_t chVTGetSystemTimeX(void);
#define chVTGetSystemTime() chVTGetSystemTimeX()
#define chTimeNow() chVTGetSystemTimeX()
#define chVTTimeElapsedSinceX(start) ((systime_t)(chVTGetSystemTimeX() - (systime_t)(start)))
#define chVTIsTimeWithinX(time, start, end) \
  ((bool)((systime_t)((systime_t)(time) - (systime_t)(start)) < \
          (systime_t)((systime_t)(end) - (systime_t)(start))))
#define chVTIsSystemTimeWithinX(start, end) chVTIsTimeWithinX(chVTGetSystemTimeX(), start, end)
#define chVTIsSystemTimeWithin(start, end) chVTIsSystemTimeWithinX(start, end)
void chVTObjectInit(virtual_timer_t *vtp);
void chVTSet(virtual_timer_t *vtp, systime_t delay, vtfunc_t vtfunc, void *par);
void chVTSetI(virtual_timer_t *vtp, systime_t delay, vtfunc_t vtfunc, void *par);
void chVTReset(virtual_timer_t *vtp);
void chVTResetI(virtual_timer_t *vtp);
bool chVTIsArmedI(virtual_timer_t *vtp);
#define chVTIsArmed(vtp) chVTIsArmedI(vtp)
void chVTDoSetI(virtual_timer_t *vtp, systime_t delay, vtfunc_t vtfunc, void *par);
void chVTDoResetI(virtual_timer_t *vtp);

/* Mutexes (not recursive, as in the kernel) */
void chMtxObjectInit(mutex_t *mp);
void chMtxLock(mutex_t *mp);
void chMtxLockS(mutex_t *mp);
bool chMtxTryLock(mutex_t *mp);
void chMtxUnlock(mutex_t *mp);
void chMtxUnlockS(mutex_t *mp);
void chMtxUnlockAll(void);
#define MUTEX_DECL(name) mutex_t name = {0, 0, 0}

/* Counting and binary semaphores */
void chSemObjectInit(semaphore_t *sp, cnt_t n);
msg_t chSemWait(semaphore_t *sp);
msg_t chSemWaitTimeout(semaphore_t *sp, systime_t time);
void chSemSignal(semaphore_t *sp);
void chSemSignalI(semaphore_t *sp);
void chSemReset(semaphore_t *sp, cnt_t n);
cnt_t chSemGetCounterI(semaphore_t *sp);
void chBSemObjectInit(binary_semaphore_t *bsp, bool taken);
msg_t chBSemWait(binary_semaphore_t *bsp);
msg_t chBSemWaitTimeout(binary_semaphore_t *bsp, systime_t time);
void chBSemSignal(binary_semaphore_t *bsp);
void chBSemSignalI(binary_semaphore_t *bsp);
void chBSemReset(binary_semaphore_t *bsp, bool taken);

/* Events */
void chEvtObjectInit(event_source_t *esp);
void chEvtRegisterMaskWithFlags(event_source_t *esp, event_listener_t *elp, eventmask_t events,
                                eventflags_t wflags);
#define chEvtRegisterMask(esp, elp, events) \
  chEvtRegisterMaskWithFlags(esp, elp, events, (eventflags_t)-1)
#define chEvtRegister(esp, elp, event) chEvtRegisterMask(esp, elp, EVENT_MASK(event))
void chEvtUnregister(event_source_t *esp, event_listener_t *elp);
void chEvtSignal(thread_t *tp, eventmask_t events);
void chEvtSignalI(thread_t *tp, eventmask_t events);
void chEvtBroadcastFlags(event_source_t *esp, eventflags_t flags);
void chEvtBroadcastFlagsI(event_source_t *esp, eventflags_t flags);
#define chEvtBroadcast(esp) chEvtBroadcastFlags(esp, 0)
#define chEvtBroadcastI(esp) chEvtBroadcastFlagsI(esp, 0)
eventmask_t chEvtWaitAny(eventmask_t events);
eventmask_t chEvtWaitAnyTimeout(eventmask_t events, systime_t time);
#define chEvtWaitOne(events) chEvtWaitAny(events)
eventmask_t chEvtGetAndClearEvents(eventmask_t events);
eventflags_t chEvtGetAndClearFlags(event_listener_t *elp);

/* Memory: the host has plenty; these report fixed figures. */
size_t chHeapStatus(void *heapp, size_t *sizep);
size_t chCoreGetStatusX(void);
void *chHeapAlloc(void *heapp, size_t size);
void chHeapFree(void *p);

#endif
