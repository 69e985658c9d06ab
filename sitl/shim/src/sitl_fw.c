/*
 * drivecheck SITL shim: the glue between the firmware's portable modules and the host (our own
 * code). This file is compiled against the firmware tree's own headers of its portable modules
 * (commands.h, packet.h, pos.h, bldc_interface.h, datatypes.h, ...) so the types and calls
 * match the tree being built; it copies nothing from them.
 *
 * - The firmware's start-up, for the portable modules of a car (MAIN_MODE_CAR), in the order a
 *   board starts them; the hardware drivers' init functions are left out.
 * - The USB serial link: the host's car-protocol bytes go through the firmware's packet.c into
 *   commands.c; what commands.c sends goes back through packet.c to the host.
 * - The VESC on the CAN bus: bldc_interface.c's packets to the motor controller are decoded
 *   into motor commands for the host; its value requests are answered with the host's motor
 *   values.
 * - GNSS: NMEA sentences from the host go to pos_input_nmea(), as the u-blox driver does.
 * - UWB: range answers from the host go to the range callback the firmware registered.
 */
#include "sitl.h"

#include "conf_general.h"
#include "datatypes.h"
#include "commands.h"
#include "packet.h"
#include "pos.h"
#include "pos_uwb.h"
#include "autopilot.h"
#include "timeout.h"
#include "motor_sim.h"
#include "bldc_interface.h"
#include "fi.h"
#include "rtcm3_simple.h"
#include "buffer.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef SITL_TIMEOUT_MS
#define SITL_TIMEOUT_MS 2000
#endif
#ifndef SITL_TIMEOUT_BRAKE
#define SITL_TIMEOUT_BRAKE 20.0
#endif
#ifndef SITL_MAIN_LOOP_MS
#define SITL_MAIN_LOOP_MS 2
#endif

void conf_general_init(void);
int sitl_hw_vesc_id(void);
void sitl_hw_deliver_range(uint8_t id, uint8_t dest, float range);
void sitl_hw_set_vin(float v);

/* ---- input queue: host inputs wait here for the shim's input thread ---- */

enum in_kind { IN_CAR_BYTES, IN_NMEA, IN_PPS, IN_UWB_RANGE, IN_MOTOR_VALUES_REPLY };

struct in_item {
  struct in_item *next;
  enum in_kind kind;
  uint8_t id, dest;
  float range;
  unsigned int len;
  unsigned char data[];
};

static struct in_item *in_head, *in_tail;
static thread_t *in_thread_tp;

static void in_push(enum in_kind kind, const unsigned char *data, unsigned int len, uint8_t id,
                    uint8_t dest, float range) {
  struct in_item *it = malloc(sizeof(struct in_item) + len + 1);
  if (!it) sitl_fatal("out of memory queueing an input");
  it->next = NULL;
  it->kind = kind;
  it->id = id;
  it->dest = dest;
  it->range = range;
  it->len = len;
  if (len) memcpy(it->data, data, len);
  it->data[len] = 0;
  if (in_tail) in_tail->next = it; else in_head = it;
  in_tail = it;
  if (in_thread_tp) chEvtSignalI(in_thread_tp, (eventmask_t)1);
}

void sitl_hw_car_bytes(const unsigned char *data, unsigned int len) {
  in_push(IN_CAR_BYTES, data, len, 0, 0, 0.0f);
}
void sitl_hw_nmea(const char *line, unsigned int len) {
  in_push(IN_NMEA, (const unsigned char *)line, len, 0, 0, 0.0f);
}
/* The receiver's PPS line: on the board an EXT interrupt (channel 8) calls pos_pps_cb. */
void sitl_hw_pps(void) { in_push(IN_PPS, NULL, 0, 0, 0, 0.0f); }
void sitl_hw_uwb_range(uint8_t id, uint8_t dest, float range) {
  in_push(IN_UWB_RANGE, NULL, 0, id, dest, range);
}

/* ---- the VESC ---- */

static mc_values motor_values;

void sitl_hw_motor_values(const float v[6]) {
  /* rpm, tachometer, tachometer_abs, v_in, current_motor, duty_now */
  motor_values.rpm = v[0];
  motor_values.tachometer = (int)v[1];
  motor_values.tachometer_abs = (int)v[2];
  motor_values.v_in = v[3];
  motor_values.current_motor = v[4];
  motor_values.duty_now = v[5];
  motor_values.temp_mos = 25.0f;
  motor_values.fault_code = FAULT_CODE_NONE;
  sitl_hw_set_vin(v[3]);
}

static float get_f32(const unsigned char *d, unsigned int len, float scale) {
  if (len < 5) return 0.0f;
  int32_t v = (int32_t)(((uint32_t)d[1] << 24) | ((uint32_t)d[2] << 16) | ((uint32_t)d[3] << 8) |
                        (uint32_t)d[4]);
  return (float)v / scale;
}

/* What bldc_interface.c sends to the motor controller. */
static void vesc_send(unsigned char *data, unsigned int len) {
  if (len < 1) return;
  switch (data[0]) {
    case COMM_GET_VALUES:
      /* answered after this call returns, as a reply over CAN would be */
      in_push(IN_MOTOR_VALUES_REPLY, NULL, 0, 0, 0, 0.0f);
      break;
    case COMM_SET_DUTY: sitl_out_motor(1, get_f32(data, len, 100000.0f)); break;
    case COMM_SET_CURRENT: sitl_out_motor(2, get_f32(data, len, 1000.0f)); break;
    case COMM_SET_CURRENT_BRAKE: sitl_out_motor(3, get_f32(data, len, 1000.0f)); break;
    case COMM_SET_RPM: sitl_out_motor(4, get_f32(data, len, 1.0f)); break;
    case COMM_SET_POS: sitl_out_motor(5, get_f32(data, len, 1000000.0f)); break;
    case COMM_SET_HANDBRAKE: sitl_out_motor(6, get_f32(data, len, 1000.0f)); break;
    default: break; /* configuration, alive, forwarded packets: nothing to drive */
  }
}

/* ---- the USB serial link ---- */

static void usb_send_raw(unsigned char *data, unsigned int len) { sitl_out_car_bytes(data, len); }

void comm_usb_send_packet(unsigned char *data, unsigned int len) {
  packet_send_packet(data, len, 0);
}

static void usb_process_packet(unsigned char *data, unsigned int len) {
  commands_process_packet(data, len, comm_usb_send_packet);
}

/* ---- the input thread ---- */

static THD_WORKING_AREA(in_thread_wa, 4096);
static THD_FUNCTION(in_thread, arg) {
  (void)arg;
  chRegSetThreadName("SitlInput");
  for (;;) {
    while (!in_head) chEvtWaitAny((eventmask_t)1);
    struct in_item *it = in_head;
    in_head = it->next;
    if (!in_head) in_tail = NULL;
    switch (it->kind) {
      case IN_CAR_BYTES:
        for (unsigned int i = 0; i < it->len; i++) packet_process_byte(it->data[i], 0);
        break;
      case IN_NMEA:
        pos_input_nmea((const char *)it->data);
        break;
      case IN_PPS:
        pos_pps_cb(&EXTD1, 8);
        break;
      case IN_UWB_RANGE:
        sitl_hw_deliver_range(it->id, it->dest, it->range);
        break;
      case IN_MOTOR_VALUES_REPLY: {
        mc_values v = motor_values;
        v.vesc_id = (uint8_t)sitl_hw_vesc_id();
        send_values_to_receiver(&v);
      } break;
    }
    free(it);
  }
}

/* ---- start-up, then the main loop's packet timer ---- */

static bool init_done;
bool sitl_fw_init_done(void) { return init_done; }

/* The yaw rotation pos.c applies to every sensor of the board: the tree's BOARD_YAW_ROT (the
 * MPU-9250's extra 180 degrees never applies here: mpu9150_is_mpu9250 is false). */
/* the configured time of a full servo sweep, s (the servo driver's ramp reads it every step) */
float sitl_fw_steering_ramp_time(void) { return main_config.car.steering_ramp_time; }

float sitl_fw_board_yaw_rot_deg(void) {
#ifdef BOARD_YAW_ROT
  return (float)(BOARD_YAW_ROT);
#else
  return 0.0f;
#endif
}

static THD_WORKING_AREA(main_thread_wa, 4096);
static THD_FUNCTION(main_thread, arg) {
  (void)arg;
  chRegSetThreadName("main");
  conf_general_init();
  sitl_hw_servo_start(); /* the board starts its servo driver before the position */
  pos_init();
  pos_uwb_init();
  bldc_interface_init(vesc_send); /* the CAN bus's VESC link */
  autopilot_init();
  timeout_init();
  motor_sim_init();
  packet_init(usb_send_raw, usb_process_packet, 0); /* the USB link */
  commands_init();
  commands_set_send_func(comm_usb_send_packet); /* the only link a SITL car has */
  motor_sim_set_running(main_config.car.simulate_motor);
  rtcm3_set_rx_callback_obs(pos_base_rtcm_obs, commands_get_rtcm3_state());
  fi_init();
  timeout_configure(SITL_TIMEOUT_MS, SITL_TIMEOUT_BRAKE);
  in_thread_tp = chThdCreateStatic(in_thread_wa, sizeof(in_thread_wa), NORMALPRIO, in_thread, NULL);
  if (in_head) chEvtSignal(in_thread_tp, (eventmask_t)1);
  init_done = true;
  sitl_out_note("init done");
  for (;;) {
    chThdSleepMilliseconds(SITL_MAIN_LOOP_MS);
    packet_timerfunc();
  }
}

void sitl_hw_start(void) {
  halInit();
  chSysInit();
  chThdCreateStatic(main_thread_wa, sizeof(main_thread_wa), NORMALPRIO, main_thread, NULL);
}

/* ---- float to integer as the Cortex-M4 converts (VCVT saturates; NaN gives 0) ----
 * buffer.c's scaled appenders are reached through the linker's --wrap, so every other module's
 * calls to them get these; the scaled product is computed in single precision like the original.
 * buffer_append_double64 is not wrapped (on the board it is a library routine, not VCVT).
 */
static int32_t sat_i32(float x) {
  if (x != x) return 0;
  if (x >= 2147483648.0f) return INT32_MAX;
  if (x <= -2147483648.0f) return INT32_MIN;
  return (int32_t)x;
}
void __wrap_buffer_append_float32(uint8_t *buffer, float number, float scale, int32_t *index) {
  buffer_append_int32(buffer, sat_i32(number * scale), index);
}
/* to int16: the processor's conversion to int32, then the low 16 bits */
void __wrap_buffer_append_float16(uint8_t *buffer, float number, float scale, int32_t *index) {
  buffer_append_int16(buffer, (int16_t)(uint16_t)(uint32_t)sat_i32(number * scale), index);
}
