/* drivecheck SITL shim: ChibiOS/RT 3.x object types (our own declarations). */
#ifndef SITL_CHSYSTYPES_H
#define SITL_CHSYSTYPES_H
#include "chtypes.h"
typedef struct ch_thread thread_t;
typedef struct ch_mutex mutex_t;
typedef struct ch_virtual_timer virtual_timer_t;
typedef struct ch_event_source event_source_t;
typedef struct ch_event_listener event_listener_t;
typedef struct ch_semaphore semaphore_t;
typedef struct ch_binary_semaphore binary_semaphore_t;
typedef void (*vtfunc_t)(void *p);
#endif
