/* drivecheck SITL shim: ChibiOS/RT 3.x scalar types (our own declarations). */
#ifndef SITL_CHTYPES_H
#define SITL_CHTYPES_H
#include <stdint.h>
#include <stdbool.h>
#include <stddef.h>
typedef uint32_t syssts_t;
typedef uint8_t tmode_t;
typedef uint8_t tstate_t;
typedef uint8_t trefs_t;
typedef uint8_t tslices_t;
typedef uint32_t tprio_t;
typedef int32_t msg_t;
typedef int32_t eventid_t;
typedef uint32_t eventmask_t;
typedef uint32_t eventflags_t;
typedef int32_t cnt_t;
typedef uint32_t ucnt_t;
typedef uint32_t systime_t;
typedef uint64_t stkalign_t;
#define ROMCONST const
#define NOINLINE __attribute__((noinline))
#define PORT_THD_FUNCTION(tname, arg) void tname(void *arg)
#define PACKED_VAR __attribute__((packed))
#define ALIGNED_VAR(n) __attribute__((aligned(n)))
#endif
