/*
 * drivecheck SITL shim: a ChibiOS/RT 3.x API subset on one virtual CPU in virtual time.
 * Written for drivecheck (MIT OR Apache-2.0); no ChibiOS code.
 *
 * Threads are coroutines, each on a stack of its own: entered the first time with makecontext/
 * swapcontext, switched afterwards with _setjmp/_longjmp, which unlike swapcontext save and
 * restore no signal mask (two system calls a switch, most of the executable's time once the
 * firmware's threads switch thousands of times a virtual second). One runs at a time, until it sleeps or blocks (cooperative:
 * there is no preemption by time slice; a thread woken by another of higher priority runs as
 * soon as the waking thread blocks or yields, and a thread that readies one of higher priority
 * yields to it). Ready threads run in priority order, FIFO within a priority. Virtual time is
 * kept in microseconds and advances only in sitl_rt_run_until(): to the next due thread wake-up
 * or virtual timer, never past the target. Same inputs, same run.
 */
#define _GNU_SOURCE
/* _FORTIFY_SOURCE's longjmp checks that the stack it jumps to is above the current one, which a
 * switch between coroutine stacks is not by design. */
#undef _FORTIFY_SOURCE
#include "sitl.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <setjmp.h>
#include <ucontext.h>

#define SITL_STACK_SIZE (256u * 1024u)

enum wait_kind { W_NONE, W_SLEEP, W_MTX, W_EVT, W_SEM, W_FINAL };

struct sitl_thread_priv {
  ucontext_t uc;  /* its first entry */
  jmp_buf jb;     /* where it left off, once it ran */
  bool started;
  void *stack;
  tfunc_t fn;
  void *arg;
  enum wait_kind wait;
  bool timed;
  uint64_t wake_us;
  uint64_t seq; /* order of becoming ready / of going to sleep */
  eventmask_t epending;
  eventmask_t ewait;
  msg_t rdymsg;
  thread_t *qnext; /* ready queue or a wait queue */
  thread_t *tnext; /* timed-wait list */
  bool terminate;
};

struct sitl_waitq {
  thread_t *head;
};

static uint64_t now_us;
static uint64_t seq_counter;
static thread_t *current;      /* NULL: the scheduler (interrupt) context */
static thread_t *ready_head;   /* sorted: priority desc, then seq asc */
static thread_t *timed_head;   /* sorted: wake_us asc, then seq asc */
static thread_t *reg_head, *reg_tail;
static virtual_timer_t *vt_head; /* sorted: due asc, then seq asc */
static ucontext_t sched_uc; /* the scheduler, while a thread runs for the first time */
static jmp_buf sched_jb;    /* the scheduler, while a thread runs */
static uint64_t switches;

uint64_t sitl_rt_now_us(void) { return now_us; }
uint64_t sitl_rt_switches(void) { return switches; }

/* When a delay of `n` ticks started now ends: at the n-th tick interrupt from now, as with the
 * kernel's periodic tick (the current, partly elapsed tick counts as the first). At least one tick. */
static uint64_t deadline(systime_t n) {
  uint64_t ticks_now = (now_us * (uint64_t)CH_CFG_ST_FREQUENCY) / 1000000ULL;
  uint64_t k = ticks_now + (n ? n : 1);
  uint64_t d = (k * 1000000ULL + (uint64_t)CH_CFG_ST_FREQUENCY - 1ULL) / (uint64_t)CH_CFG_ST_FREQUENCY;
  return d > now_us ? d : now_us + 1;
}

systime_t chVTGetSystemTimeX(void) {
  return (systime_t)((now_us * (uint64_t)CH_CFG_ST_FREQUENCY) / 1000000ULL);
}

/* ---- queues ---- */

static void ready_insert(thread_t *tp) {
  tp->priv->seq = ++seq_counter;
  tp->priv->wait = W_NONE;
  tp->p_state = CH_STATE_READY;
  thread_t **pp = &ready_head;
  while (*pp && (*pp)->p_prio >= tp->p_prio) pp = &(*pp)->priv->qnext;
  tp->priv->qnext = *pp;
  *pp = tp;
}

static void timed_insert(thread_t *tp, uint64_t wake_us) {
  tp->priv->timed = true;
  tp->priv->wake_us = wake_us;
  tp->priv->seq = ++seq_counter;
  thread_t **pp = &timed_head;
  while (*pp && (*pp)->priv->wake_us <= wake_us) pp = &(*pp)->priv->tnext;
  tp->priv->tnext = *pp;
  *pp = tp;
}

static void timed_remove(thread_t *tp) {
  if (!tp->priv->timed) return;
  for (thread_t **pp = &timed_head; *pp; pp = &(*pp)->priv->tnext) {
    if (*pp == tp) {
      *pp = tp->priv->tnext;
      break;
    }
  }
  tp->priv->timed = false;
}

static void waitq_push(struct sitl_waitq **qp, thread_t *tp) {
  if (!*qp) {
    *qp = calloc(1, sizeof(struct sitl_waitq));
    if (!*qp) sitl_fatal("out of memory");
  }
  /* priority order, FIFO within a priority, as the kernel queues waiters */
  thread_t **pp = &(*qp)->head;
  while (*pp && (*pp)->p_prio >= tp->p_prio) pp = &(*pp)->priv->qnext;
  tp->priv->qnext = *pp;
  *pp = tp;
}

static thread_t *waitq_pop(struct sitl_waitq *q) {
  if (!q || !q->head) return NULL;
  thread_t *tp = q->head;
  q->head = tp->priv->qnext;
  tp->priv->qnext = NULL;
  return tp;
}

static void waitq_remove(struct sitl_waitq *q, thread_t *tp) {
  if (!q) return;
  for (thread_t **pp = &q->head; *pp; pp = &(*pp)->priv->qnext) {
    if (*pp == tp) {
      *pp = tp->priv->qnext;
      return;
    }
  }
}

/* ---- switching ---- */

static void need_thread(const char *what) {
  if (!current) {
    char msg[160];
    snprintf(msg, sizeof msg, "%s called from interrupt (timer callback) context", what);
    sitl_fatal(msg);
  }
}

/* Leaves the current thread (already queued wherever it waits) and returns when it runs again. */
static void block_current(void) {
  thread_t *self = current;
  current = NULL;
  if (!_setjmp(self->priv->jb)) _longjmp(sched_jb, 1);
}

/* A thread made ready by the current thread: it runs first if its priority is higher. */
static void wakeup(thread_t *tp, msg_t msg) {
  timed_remove(tp);
  tp->priv->rdymsg = msg;
  ready_insert(tp);
  if (current && tp->p_prio > current->p_prio) {
    ready_insert(current);
    block_current();
  }
}

static void thread_entry(void) {
  thread_t *self = current;
  self->priv->fn(self->priv->arg);
  chThdExit(MSG_OK);
}

thread_t *chThdCreateStatic(void *wsp, size_t size, tprio_t prio, tfunc_t pf, void *arg) {
  (void)wsp;
  (void)size;
  thread_t *tp = calloc(1, sizeof(thread_t));
  struct sitl_thread_priv *p = calloc(1, sizeof(struct sitl_thread_priv));
  void *stack = malloc(SITL_STACK_SIZE);
  if (!tp || !p || !stack) sitl_fatal("out of memory creating a thread");
  tp->priv = p;
  tp->p_prio = prio;
  tp->p_refs = 1;
  tp->p_name = "noname";
  tp->p_ctx.r13 = stack;
  p->stack = stack;
  p->fn = pf;
  p->arg = arg;
  getcontext(&p->uc);
  p->uc.uc_stack.ss_sp = stack;
  p->uc.uc_stack.ss_size = SITL_STACK_SIZE;
  p->uc.uc_link = NULL;
  makecontext(&p->uc, thread_entry, 0);
  if (reg_tail) reg_tail->reg_next = tp; else reg_head = tp;
  reg_tail = tp;
  ready_insert(tp);
  if (current && prio > current->p_prio) {
    ready_insert(current);
    block_current();
  }
  return tp;
}

void chThdExit(msg_t msg) {
  (void)msg;
  need_thread("chThdExit");
  current->priv->wait = W_FINAL;
  current->p_state = CH_STATE_FINAL;
  block_current();
  sitl_fatal("a finished thread was resumed");
}

thread_t *chThdGetSelfX(void) { return current; }

void chThdSleep(systime_t time) {
  need_thread("chThdSleep");
  if (time == TIME_IMMEDIATE) {
    chThdYield();
    return;
  }
  thread_t *self = current;
  self->priv->wait = W_SLEEP;
  self->p_state = CH_STATE_SLEEPING;
  timed_insert(self, deadline(time));
  block_current();
}

void chThdSleepUntil(systime_t time) {
  systime_t d = (systime_t)(time - chVTGetSystemTimeX());
  if (d > 0) chThdSleep(d);
}

systime_t chThdSleepUntilWindowed(systime_t prev, systime_t next) {
  systime_t t = chVTGetSystemTimeX();
  if (chVTIsTimeWithinX(t, prev, next)) chThdSleep((systime_t)(next - t));
  return next;
}

void chThdYield(void) {
  need_thread("chThdYield");
  ready_insert(current);
  block_current();
}

bool chThdShouldTerminateX(void) { return current && current->priv->terminate; }
void chThdTerminate(thread_t *tp) { tp->priv->terminate = true; }
tprio_t chThdGetPriorityX(void) { return current ? current->p_prio : HIGHPRIO; }
tprio_t chThdSetPriority(tprio_t newprio) {
  need_thread("chThdSetPriority");
  tprio_t old = current->p_prio;
  current->p_prio = newprio;
  return old;
}

void chRegSetThreadName(const char *name) {
  if (current) current->p_name = name;
}
thread_t *chRegFirstThread(void) { return reg_head; }
thread_t *chRegNextThread(thread_t *tp) { return tp ? tp->reg_next : NULL; }

/* ---- system ---- */

void chSysInit(void) {}
void chSysHalt(const char *reason) { sitl_fatal(reason ? reason : "chSysHalt"); }
void chSysLock(void) {}
void chSysUnlock(void) {}
void chSysLockFromISR(void) {}
void chSysUnlockFromISR(void) {}
void chSchRescheduleS(void) {
  if (current && ready_head && ready_head->p_prio > current->p_prio) chThdYield();
}

size_t chHeapStatus(void *heapp, size_t *sizep) {
  (void)heapp;
  if (sizep) *sizep = 0;
  return 0;
}
size_t chCoreGetStatusX(void) { return 0; }
void *chHeapAlloc(void *heapp, size_t size) {
  (void)heapp;
  return malloc(size);
}
void chHeapFree(void *p) { free(p); }

/* ---- virtual timers: callbacks run in the scheduler (interrupt) context ---- */

void chVTObjectInit(virtual_timer_t *vtp) { memset(vtp, 0, sizeof *vtp); }

void chVTDoResetI(virtual_timer_t *vtp) {
  for (virtual_timer_t **pp = &vt_head; *pp; pp = &(*pp)->next) {
    if (*pp == vtp) {
      *pp = vtp->next;
      break;
    }
  }
  vtp->armed = false;
  vtp->next = NULL;
}

void chVTDoSetI(virtual_timer_t *vtp, systime_t delay, vtfunc_t vtfunc, void *par) {
  if (vtp->armed) chVTDoResetI(vtp);
  vtp->due_us = deadline(delay);
  vtp->seq = ++seq_counter;
  vtp->func = vtfunc;
  vtp->par = par;
  vtp->armed = true;
  virtual_timer_t **pp = &vt_head;
  while (*pp && (*pp)->due_us <= vtp->due_us) pp = &(*pp)->next;
  vtp->next = *pp;
  *pp = vtp;
}

void chVTSet(virtual_timer_t *vtp, systime_t delay, vtfunc_t vtfunc, void *par) {
  chVTDoSetI(vtp, delay, vtfunc, par);
}
void chVTSetI(virtual_timer_t *vtp, systime_t delay, vtfunc_t vtfunc, void *par) {
  chVTDoSetI(vtp, delay, vtfunc, par);
}
void chVTReset(virtual_timer_t *vtp) { chVTDoResetI(vtp); }
void chVTResetI(virtual_timer_t *vtp) { chVTDoResetI(vtp); }
bool chVTIsArmedI(virtual_timer_t *vtp) { return vtp->armed; }

/* ---- mutexes ---- */

void chMtxObjectInit(mutex_t *mp) { memset(mp, 0, sizeof *mp); }

void chMtxLock(mutex_t *mp) {
  need_thread("chMtxLock");
  if (!mp->owner) {
    mp->owner = current;
    return;
  }
  if (mp->owner == current) {
    char msg[200];
    snprintf(msg, sizeof msg,
             "deadlock: thread '%s' locks a mutex it already holds (mutexes are not recursive)",
             current->p_name);
    sitl_fatal(msg);
  }
  thread_t *self = current;
  self->priv->wait = W_MTX;
  self->p_state = CH_STATE_WTMTX;
  waitq_push(&mp->waiters, self);
  block_current();
  /* ownership was handed over by the unlocker */
}
void chMtxLockS(mutex_t *mp) { chMtxLock(mp); }

bool chMtxTryLock(mutex_t *mp) {
  if (mp->owner) return false;
  mp->owner = current;
  return true;
}

void chMtxUnlock(mutex_t *mp) {
  thread_t *next = waitq_pop(mp->waiters);
  mp->owner = next;
  if (next) wakeup(next, MSG_OK);
}
void chMtxUnlockS(mutex_t *mp) { chMtxUnlock(mp); }
void chMtxUnlockAll(void) {}

/* ---- semaphores ---- */

void chSemObjectInit(semaphore_t *sp, cnt_t n) {
  sp->cnt = n;
  sp->waiters = NULL;
}

msg_t chSemWaitTimeout(semaphore_t *sp, systime_t time) {
  need_thread("chSemWait");
  if (sp->cnt > 0) {
    sp->cnt--;
    return MSG_OK;
  }
  if (time == TIME_IMMEDIATE) return MSG_TIMEOUT;
  thread_t *self = current;
  self->priv->wait = W_SEM;
  self->p_state = CH_STATE_WTSEM;
  self->priv->rdymsg = MSG_TIMEOUT;
  waitq_push(&sp->waiters, self);
  if (time != TIME_INFINITE) timed_insert(self, deadline(time));
  block_current();
  if (self->priv->rdymsg == MSG_TIMEOUT) waitq_remove(sp->waiters, self);
  return self->priv->rdymsg;
}
msg_t chSemWait(semaphore_t *sp) { return chSemWaitTimeout(sp, TIME_INFINITE); }

void chSemSignal(semaphore_t *sp) {
  thread_t *tp = waitq_pop(sp->waiters);
  if (tp) wakeup(tp, MSG_OK); else sp->cnt++;
}
void chSemSignalI(semaphore_t *sp) {
  thread_t *tp = waitq_pop(sp->waiters);
  if (tp) {
    timed_remove(tp);
    tp->priv->rdymsg = MSG_OK;
    ready_insert(tp);
  } else {
    sp->cnt++;
  }
}
void chSemReset(semaphore_t *sp, cnt_t n) {
  thread_t *tp;
  while ((tp = waitq_pop(sp->waiters))) {
    timed_remove(tp);
    tp->priv->rdymsg = MSG_RESET;
    ready_insert(tp);
  }
  sp->cnt = n;
}
cnt_t chSemGetCounterI(semaphore_t *sp) { return sp->cnt; }

void chBSemObjectInit(binary_semaphore_t *bsp, bool taken) { chSemObjectInit(&bsp->sem, taken ? 0 : 1); }
msg_t chBSemWait(binary_semaphore_t *bsp) { return chSemWait(&bsp->sem); }
msg_t chBSemWaitTimeout(binary_semaphore_t *bsp, systime_t time) { return chSemWaitTimeout(&bsp->sem, time); }
void chBSemSignal(binary_semaphore_t *bsp) {
  if (bsp->sem.cnt < 1) chSemSignal(&bsp->sem);
}
void chBSemSignalI(binary_semaphore_t *bsp) {
  if (bsp->sem.cnt < 1) chSemSignalI(&bsp->sem);
}
void chBSemReset(binary_semaphore_t *bsp, bool taken) { chSemReset(&bsp->sem, taken ? 0 : 1); }

/* ---- events ---- */

static void evt_signal(thread_t *tp, eventmask_t events, bool may_switch) {
  tp->priv->epending |= events;
  if (tp->priv->wait == W_EVT && (tp->priv->epending & tp->priv->ewait)) {
    if (may_switch) {
      wakeup(tp, MSG_OK);
    } else {
      timed_remove(tp);
      tp->priv->rdymsg = MSG_OK;
      ready_insert(tp);
    }
  }
}
void chEvtSignal(thread_t *tp, eventmask_t events) { evt_signal(tp, events, true); }
void chEvtSignalI(thread_t *tp, eventmask_t events) { evt_signal(tp, events, false); }

eventmask_t chEvtWaitAnyTimeout(eventmask_t events, systime_t time) {
  need_thread("chEvtWaitAny");
  thread_t *self = current;
  eventmask_t m = self->priv->epending & events;
  if (!m) {
    if (time == TIME_IMMEDIATE) return 0;
    self->priv->ewait = events;
    self->priv->wait = W_EVT;
    self->p_state = CH_STATE_WTOREVT;
    if (time != TIME_INFINITE) timed_insert(self, deadline(time));
    block_current();
    m = self->priv->epending & events;
  }
  self->priv->epending &= ~m;
  return m;
}
eventmask_t chEvtWaitAny(eventmask_t events) { return chEvtWaitAnyTimeout(events, TIME_INFINITE); }

eventmask_t chEvtGetAndClearEvents(eventmask_t events) {
  need_thread("chEvtGetAndClearEvents");
  eventmask_t m = current->priv->epending & events;
  current->priv->epending &= ~m;
  return m;
}

void chEvtObjectInit(event_source_t *esp) { esp->next = NULL; }
void chEvtRegisterMaskWithFlags(event_source_t *esp, event_listener_t *elp, eventmask_t events,
                                eventflags_t wflags) {
  elp->listener = current;
  elp->events = events;
  elp->flags = 0;
  elp->wflags = wflags;
  elp->next = esp->next;
  esp->next = elp;
}
void chEvtUnregister(event_source_t *esp, event_listener_t *elp) {
  for (event_listener_t **pp = &esp->next; *pp; pp = &(*pp)->next) {
    if (*pp == elp) {
      *pp = elp->next;
      return;
    }
  }
}
void chEvtBroadcastFlagsI(event_source_t *esp, eventflags_t flags) {
  for (event_listener_t *elp = esp->next; elp; elp = elp->next) {
    elp->flags |= flags;
    if (flags == 0 || (elp->flags & elp->wflags)) evt_signal(elp->listener, elp->events, false);
  }
}
void chEvtBroadcastFlags(event_source_t *esp, eventflags_t flags) {
  chEvtBroadcastFlagsI(esp, flags);
  chSchRescheduleS();
}
eventflags_t chEvtGetAndClearFlags(event_listener_t *elp) {
  eventflags_t f = elp->flags;
  elp->flags = 0;
  return f;
}

/* ---- the scheduler loop ---- */

static void run_ready(void) {
  while (ready_head) {
    thread_t *tp = ready_head;
    ready_head = tp->priv->qnext;
    tp->priv->qnext = NULL;
    tp->p_state = CH_STATE_CURRENT;
    current = tp;
    switches++;
    if (!_setjmp(sched_jb)) {
      if (tp->priv->started) {
        _longjmp(tp->priv->jb, 1);
      }
      tp->priv->started = true;
      swapcontext(&sched_uc, &tp->priv->uc);
    }
    current = NULL;
  }
}

void sitl_rt_run_until(uint64_t target_us) {
  for (;;) {
    run_ready();
    uint64_t next = UINT64_MAX;
    if (timed_head) next = timed_head->priv->wake_us;
    if (vt_head && vt_head->due_us < next) next = vt_head->due_us;
    if (next > target_us) {
      if (target_us > now_us) now_us = target_us;
      return;
    }
    if (next > now_us) now_us = next;
    /* timers first (interrupts), then the threads whose wake-up is due, in order */
    while (vt_head && vt_head->due_us <= now_us) {
      virtual_timer_t *vtp = vt_head;
      vt_head = vtp->next;
      vtp->next = NULL;
      vtp->armed = false;
      vtp->func(vtp->par);
    }
    while (timed_head && timed_head->priv->wake_us <= now_us) {
      thread_t *tp = timed_head;
      timed_head = tp->priv->tnext;
      tp->priv->timed = false;
      if (tp->priv->wait == W_SEM) {
        /* left in the semaphore's queue; the waiter removes itself on MSG_TIMEOUT */
        tp->priv->rdymsg = MSG_TIMEOUT;
      } else {
        tp->priv->rdymsg = MSG_TIMEOUT;
      }
      ready_insert(tp);
    }
  }
}

/* Runs what is ready now, without advancing time. */
void sitl_rt_run_ready(void) { run_ready(); }
