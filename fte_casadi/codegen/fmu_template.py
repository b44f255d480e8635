"""Template of the FMI 2.0 co-simulation wrapper around the generated step (see :mod:`.fmu`).

The wrapper is the only file of the FMU that calls the C library (``vsnprintf`` for the log
messages, ``strlen``/``memcpy``/``memset``); the generated step it wraps stays free of I/O and
heap. Instance memory comes from the environment's ``allocateMemory`` callback.
"""

from __future__ import annotations

from string import Template

__all__ = ["WRAPPER", "FMI2_HEADER", "FMI2_HEADER_NAME"]

#: file name of :data:`FMI2_HEADER` in the FMU's sources
FMI2_HEADER_NAME = "fte_fmi2.h"

#: The declarations of the FMI 2.0 C API this wrapper needs (types, callbacks, the common and the
#: co-simulation functions), written for fte_casadi from the FMI 2.0 standard's interface
#: (ABI-compatible with the standard's fmi2Functions.h, platform "default"). An importer that
#: compiles the sources for static linking defines FMI2_FUNCTION_PREFIX, as with the standard headers.
FMI2_HEADER = """\
/* fte_fmi2.h -- the FMI 2.0 C interface (types, callbacks, common and co-simulation functions) as
 * the FMI 2.0 standard defines it, platform "default"; written for fte_casadi's FMUs.
 * Define FMI2_FUNCTION_PREFIX (e.g. MyModel_) to prefix every function name, as for a source-code
 * FMU compiled into a static library; without it the functions are exported unprefixed. */
#ifndef FTE_FMI2_H
#define FTE_FMI2_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#define fmi2TypesPlatform "default"
#define fmi2Version "2.0"

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;

#define fmi2True 1
#define fmi2False 0

typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;

typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment componentEnvironment, fmi2String instanceName,
                                   fmi2Status status, fmi2String category, fmi2String message, ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t nobj, size_t size);
typedef void (*fmi2CallbackFreeMemory)(void *obj);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment componentEnvironment, fmi2Status status);

typedef struct {
  fmi2CallbackLogger logger;
  fmi2CallbackAllocateMemory allocateMemory;
  fmi2CallbackFreeMemory freeMemory;
  fmi2StepFinished stepFinished;
  fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

#ifdef FMI2_FUNCTION_PREFIX
#define FTE_FMI2_PASTE(a, b) a##b
#define FTE_FMI2_JOIN(a, b) FTE_FMI2_PASTE(a, b)
#define FTE_FMI2_NAME(name) FTE_FMI2_JOIN(FMI2_FUNCTION_PREFIX, name)
#define FTE_FMI2_EXPORT
#else
#define FTE_FMI2_NAME(name) name
#if defined _WIN32 || defined __CYGWIN__
#define FTE_FMI2_EXPORT __declspec(dllexport)
#elif defined __GNUC__ && __GNUC__ >= 4
#define FTE_FMI2_EXPORT __attribute__((visibility("default")))
#else
#define FTE_FMI2_EXPORT
#endif
#endif

#define fmi2GetTypesPlatform FTE_FMI2_NAME(fmi2GetTypesPlatform)
#define fmi2GetVersion FTE_FMI2_NAME(fmi2GetVersion)
#define fmi2SetDebugLogging FTE_FMI2_NAME(fmi2SetDebugLogging)
#define fmi2Instantiate FTE_FMI2_NAME(fmi2Instantiate)
#define fmi2FreeInstance FTE_FMI2_NAME(fmi2FreeInstance)
#define fmi2SetupExperiment FTE_FMI2_NAME(fmi2SetupExperiment)
#define fmi2EnterInitializationMode FTE_FMI2_NAME(fmi2EnterInitializationMode)
#define fmi2ExitInitializationMode FTE_FMI2_NAME(fmi2ExitInitializationMode)
#define fmi2Terminate FTE_FMI2_NAME(fmi2Terminate)
#define fmi2Reset FTE_FMI2_NAME(fmi2Reset)
#define fmi2GetReal FTE_FMI2_NAME(fmi2GetReal)
#define fmi2GetInteger FTE_FMI2_NAME(fmi2GetInteger)
#define fmi2GetBoolean FTE_FMI2_NAME(fmi2GetBoolean)
#define fmi2GetString FTE_FMI2_NAME(fmi2GetString)
#define fmi2SetReal FTE_FMI2_NAME(fmi2SetReal)
#define fmi2SetInteger FTE_FMI2_NAME(fmi2SetInteger)
#define fmi2SetBoolean FTE_FMI2_NAME(fmi2SetBoolean)
#define fmi2SetString FTE_FMI2_NAME(fmi2SetString)
#define fmi2GetFMUstate FTE_FMI2_NAME(fmi2GetFMUstate)
#define fmi2SetFMUstate FTE_FMI2_NAME(fmi2SetFMUstate)
#define fmi2FreeFMUstate FTE_FMI2_NAME(fmi2FreeFMUstate)
#define fmi2SerializedFMUstateSize FTE_FMI2_NAME(fmi2SerializedFMUstateSize)
#define fmi2SerializeFMUstate FTE_FMI2_NAME(fmi2SerializeFMUstate)
#define fmi2DeSerializeFMUstate FTE_FMI2_NAME(fmi2DeSerializeFMUstate)
#define fmi2GetDirectionalDerivative FTE_FMI2_NAME(fmi2GetDirectionalDerivative)
#define fmi2SetRealInputDerivatives FTE_FMI2_NAME(fmi2SetRealInputDerivatives)
#define fmi2GetRealOutputDerivatives FTE_FMI2_NAME(fmi2GetRealOutputDerivatives)
#define fmi2DoStep FTE_FMI2_NAME(fmi2DoStep)
#define fmi2CancelStep FTE_FMI2_NAME(fmi2CancelStep)
#define fmi2GetStatus FTE_FMI2_NAME(fmi2GetStatus)
#define fmi2GetRealStatus FTE_FMI2_NAME(fmi2GetRealStatus)
#define fmi2GetIntegerStatus FTE_FMI2_NAME(fmi2GetIntegerStatus)
#define fmi2GetBooleanStatus FTE_FMI2_NAME(fmi2GetBooleanStatus)
#define fmi2GetStringStatus FTE_FMI2_NAME(fmi2GetStringStatus)

typedef const fmi2ValueReference fmi2VR; /* shorthand of this header only */

FTE_FMI2_EXPORT const char *fmi2GetTypesPlatform(void);
FTE_FMI2_EXPORT const char *fmi2GetVersion(void);
FTE_FMI2_EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                                               const fmi2String categories[]);
FTE_FMI2_EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                              fmi2String fmuResourceLocation,
                                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                                              fmi2Boolean loggingOn);
FTE_FMI2_EXPORT void fmi2FreeInstance(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                                               fmi2Real tolerance, fmi2Real startTime,
                                               fmi2Boolean stopTimeDefined, fmi2Real stopTime);
FTE_FMI2_EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2Terminate(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2Reset(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2GetReal(fmi2Component c, fmi2VR vr[], size_t nvr, fmi2Real value[]);
FTE_FMI2_EXPORT fmi2Status fmi2GetInteger(fmi2Component c, fmi2VR vr[], size_t nvr, fmi2Integer value[]);
FTE_FMI2_EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, fmi2VR vr[], size_t nvr, fmi2Boolean value[]);
FTE_FMI2_EXPORT fmi2Status fmi2GetString(fmi2Component c, fmi2VR vr[], size_t nvr, fmi2String value[]);
FTE_FMI2_EXPORT fmi2Status fmi2SetReal(fmi2Component c, fmi2VR vr[], size_t nvr, const fmi2Real value[]);
FTE_FMI2_EXPORT fmi2Status fmi2SetInteger(fmi2Component c, fmi2VR vr[], size_t nvr, const fmi2Integer value[]);
FTE_FMI2_EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, fmi2VR vr[], size_t nvr, const fmi2Boolean value[]);
FTE_FMI2_EXPORT fmi2Status fmi2SetString(fmi2Component c, fmi2VR vr[], size_t nvr, const fmi2String value[]);
FTE_FMI2_EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate);
FTE_FMI2_EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate);
FTE_FMI2_EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate);
FTE_FMI2_EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size);
FTE_FMI2_EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                                 fmi2Byte serializedState[], size_t size);
FTE_FMI2_EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                                   size_t size, fmi2FMUstate *FMUstate);
FTE_FMI2_EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, fmi2VR vUnknown_ref[], size_t nUnknown,
                                                        fmi2VR vKnown_ref[], size_t nKnown,
                                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]);
FTE_FMI2_EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, fmi2VR vr[], size_t nvr,
                                                       const fmi2Integer order[], const fmi2Real value[]);
FTE_FMI2_EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, fmi2VR vr[], size_t nvr,
                                                        const fmi2Integer order[], fmi2Real value[]);
FTE_FMI2_EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                                      fmi2Real communicationStepSize,
                                      fmi2Boolean noSetFMUStatePriorToCurrentPoint);
FTE_FMI2_EXPORT fmi2Status fmi2CancelStep(fmi2Component c);
FTE_FMI2_EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value);
FTE_FMI2_EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value);
FTE_FMI2_EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value);
FTE_FMI2_EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value);
FTE_FMI2_EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* FTE_FMI2_H */
"""

WRAPPER = Template(
    """\
/* ${mid}_fmi2.c -- FMI 2.0 co-simulation interface of the observer / fault estimator / tolerant
 * controller of plant "${plant}" (fte_${name}.h).
 * Generated by fte_casadi ${version} (do not edit; regenerate with `fte codegen ... --fmu`).
 *
 * Inputs y (value references 0..${ny_last}); outputs u, xbarhat, yc (${ny}..${nvar_last}).
 * One fmi2DoStep of the fixed step Ts = ${sample_time_text} is one sample of the discrete step:
 *   - the sample is taken from the inputs as last set (the measurements y_k at the step's start);
 *   - the first fmi2DoStep starts the observer from that first measurement, as fte simulate does:
 *     fte_${name}_init_from_y(y_0, xbar0 of the design), then the step on y_0 itself;
 *   - the outputs are that sample's u_k, xbarhat_k, yc_k; they are held until new inputs are set.
 * Outputs read after new inputs were set (and before the next fmi2DoStep) are computed at once
 * from the current observer state and those inputs (direct feedthrough, no state change), so a
 * master that sets y_k and then reads gets u_k at t_k; one that reads first gets the held u_{k-1}.
 */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fte_fmi2.h"
#include "fte_${name}.h"

#define NY FTE_${NAME}_NY
#define NU FTE_${NAME}_NU
#define NXBAR FTE_${NAME}_NXBAR
#define NOUT (NU + NXBAR + NY)
#define NVAR (NY + NOUT)
#define GUID "${guid}"
#define TS ((fmi2Real)FTE_${NAME}_TS)
/* a communication step is accepted when it is Ts within this relative tolerance (round-off of
 * a master's time grid t_k = t_0 + k Ts) */
#define STEP_RTOL 1e-6

static const fmi2Real y_start[NY] = {
${y_start}
};

static const char *const var_names[NVAR] = {
${var_names}
};

typedef enum { PHASE_INSTANTIATED, PHASE_INIT, PHASE_STEP, PHASE_TERMINATED } phase_t;

typedef struct {
  fte_${name}_state st;     /* observer state z_k (valid once started) */
  fmi2Real y[NY];           /* the inputs as last set */
  fmi2Real out[NOUT];       /* u, xbarhat, yc of the last sample */
  int started;              /* the first fmi2DoStep has taken the first measurement */
  int fresh;                /* out[] belongs to the current inputs (or to the last step) */
  int logging;              /* fmi2SetDebugLogging: log OK-status messages too */
  phase_t phase;
  fmi2Real time;            /* the current communication point */
  char *name;
  fmi2ComponentEnvironment env;
  fmi2CallbackLogger logger;
  fmi2CallbackFreeMemory free_memory;
} instance;

/* Errors are always logged (category logStatusError); OK-status messages only with debug logging on.
 * The logger treats the message as a printf format: format here, then double every '%'. */
static void log_msg(const instance *c, fmi2Status status, const char *fmt, ...) {
  char buf[600], safe[1200];
  size_t i, k = 0;
  va_list ap;
  if (c == NULL || c->logger == NULL) return;
  if (status == fmi2OK && !c->logging) return;
  va_start(ap, fmt);
  vsnprintf(buf, sizeof buf, fmt, ap);
  va_end(ap);
  for (i = 0; buf[i] != '\\0' && k + 2 < sizeof safe; ++i) {
    if (buf[i] == '%') safe[k++] = '%';
    safe[k++] = buf[i];
  }
  safe[k] = '\\0';
  c->logger(c->env, c->name, status, "logStatusError", safe);
}

static int is_finite(fmi2Real v) { return v - v == 0; } /* NaN and +-inf fail (IEEE) */

/* One sample from the inputs into out[]; st starts from the inputs first when start is set.
 * Returns 0, or the code of fte_${name}_init_from_y / fte_${name}_step (st untouched then). */
static int take_sample(const instance *c, fte_${name}_state *st, fmi2Real *out, int start) {
  fte_real y[NY], u[NU], xb[NXBAR], yc[NY];
  int i, rc;
  for (i = 0; i < NY; ++i) y[i] = (fte_real)c->y[i];
  if (start) {
    rc = fte_${name}_init_from_y(st, y, NULL);
    if (rc != 0) return rc;
  }
  rc = fte_${name}_step(st, y, u, xb, yc);
  if (rc != 0) return rc;
  for (i = 0; i < NU; ++i) out[i] = (fmi2Real)u[i];
  for (i = 0; i < NXBAR; ++i) out[NU + i] = (fmi2Real)xb[i];
  for (i = 0; i < NY; ++i) out[NU + NXBAR + i] = (fmi2Real)yc[i];
  return 0;
}

static fmi2Status sample_failed(const instance *c, int rc, const char *where) {
  if (rc == 1)
    log_msg(c, fmi2Error, "%s at t = %.17g: a measurement is not finite in the step's real type "
            "(fte_real); the observer state is kept", where, c->time);
  else
    log_msg(c, fmi2Error, "%s at t = %.17g: the generated step returned %d", where, c->time, rc);
  return fmi2Error;
}

/* out[] for the current inputs, computed on a copy of the state (the state does not move). */
static fmi2Status refresh(instance *c) {
  fte_${name}_state tmp;
  int rc;
  if (c->fresh) return fmi2OK;
  tmp = c->st;
  rc = take_sample(c, &tmp, c->out, !c->started);
  if (rc != 0) return sample_failed(c, rc, "fmi2GetReal");
  c->fresh = 1;
  return fmi2OK;
}

static void restart(instance *c) {
  int i;
  memset(&c->st, 0, sizeof c->st);
  for (i = 0; i < NY; ++i) c->y[i] = y_start[i];
  for (i = 0; i < NOUT; ++i) c->out[i] = 0;
  c->started = 0;
  c->fresh = 0;
  c->time = 0;
  c->phase = PHASE_INSTANTIATED;
}

static fmi2Status wrong_phase(instance *c, const char *fn) {
  static const char *const names[] = {"instantiated", "initialization mode", "step mode", "terminated"};
  log_msg(c, fmi2Error, "%s is not allowed when the FMU is %s", fn, names[c->phase]);
  return fmi2Error;
}

#define CHECK_INSTANCE(c) \\
  if ((c) == NULL) return fmi2Error

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
  instance *c = (instance *)comp;
  CHECK_INSTANCE(c);
  (void)nCategories;
  (void)categories;
  c->logging = loggingOn ? 1 : 0;
  return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
  instance *c;
  const char *nm = instanceName ? instanceName : "";
  size_t len = strlen(nm);
  (void)fmuResourceLocation;
  (void)visible;
  if (functions == NULL || functions->allocateMemory == NULL || functions->freeMemory == NULL) return NULL;
  if (fmuType != fmi2CoSimulation) {
    if (functions->logger)
      functions->logger(functions->componentEnvironment, nm, fmi2Error, "logStatusError",
                        "this FMU supports co-simulation only (fmi2CoSimulation), not model exchange");
    return NULL;
  }
  if (fmuGUID == NULL || strcmp(fmuGUID, GUID) != 0) {
    if (functions->logger)
      functions->logger(functions->componentEnvironment, nm, fmi2Error, "logStatusError",
                        "the GUID does not match this binary's (" GUID "): modelDescription.xml and "
                        "binary come from different `fte codegen --fmu` runs");
    return NULL;
  }
  c = (instance *)functions->allocateMemory(1, sizeof(instance));
  if (c == NULL) return NULL;
  memset(c, 0, sizeof *c);
  c->name = (char *)functions->allocateMemory(len + 1, 1);
  if (c->name == NULL) {
    functions->freeMemory(c);
    return NULL;
  }
  memcpy(c->name, nm, len + 1);
  c->env = functions->componentEnvironment;
  c->logger = functions->logger;
  c->free_memory = functions->freeMemory;
  c->logging = loggingOn ? 1 : 0;
  restart(c);
  return (fmi2Component)c;
}

void fmi2FreeInstance(fmi2Component comp) {
  instance *c = (instance *)comp;
  fmi2CallbackFreeMemory free_memory;
  if (c == NULL) return;
  free_memory = c->free_memory;
  free_memory(c->name);
  free_memory(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
  instance *c = (instance *)comp;
  CHECK_INSTANCE(c);
  (void)toleranceDefined;
  (void)tolerance;
  (void)stopTimeDefined;
  (void)stopTime;
  if (c->phase != PHASE_INSTANTIATED) return wrong_phase(c, "fmi2SetupExperiment");
  c->time = startTime;
  return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
  instance *c = (instance *)comp;
  CHECK_INSTANCE(c);
  if (c->phase != PHASE_INSTANTIATED) return wrong_phase(c, "fmi2EnterInitializationMode");
  c->phase = PHASE_INIT;
  return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
  instance *c = (instance *)comp;
  CHECK_INSTANCE(c);
  if (c->phase != PHASE_INIT) return wrong_phase(c, "fmi2ExitInitializationMode");
  c->phase = PHASE_STEP;
  return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
  instance *c = (instance *)comp;
  CHECK_INSTANCE(c);
  if (c->phase != PHASE_STEP && c->phase != PHASE_INIT) return wrong_phase(c, "fmi2Terminate");
  c->phase = PHASE_TERMINATED;
  return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
  instance *c = (instance *)comp;
  CHECK_INSTANCE(c);
  restart(c);
  return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
  instance *c = (instance *)comp;
  size_t k;
  int outputs = 0;
  CHECK_INSTANCE(c);
  if (nvr == 0) return fmi2OK;
  if (vr == NULL || value == NULL) {
    log_msg(c, fmi2Error, "fmi2GetReal: NULL value reference or value array");
    return fmi2Error;
  }
  for (k = 0; k < nvr; ++k) {
    if (vr[k] >= NVAR) {
      log_msg(c, fmi2Error, "fmi2GetReal: unknown value reference %u (this FMU has 0..%d)",
              (unsigned)vr[k], NVAR - 1);
      return fmi2Error;
    }
    if (vr[k] >= NY) outputs = 1;
  }
  if (outputs && refresh(c) != fmi2OK) return fmi2Error;
  for (k = 0; k < nvr; ++k) value[k] = vr[k] < NY ? c->y[vr[k]] : c->out[vr[k] - NY];
  return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
  instance *c = (instance *)comp;
  size_t k;
  CHECK_INSTANCE(c);
  if (nvr == 0) return fmi2OK;
  if (c->phase == PHASE_TERMINATED) return wrong_phase(c, "fmi2SetReal");
  if (vr == NULL || value == NULL) {
    log_msg(c, fmi2Error, "fmi2SetReal: NULL value reference or value array");
    return fmi2Error;
  }
  for (k = 0; k < nvr; ++k) { /* check all first: nothing is set when one is refused */
    if (vr[k] >= NVAR) {
      log_msg(c, fmi2Error, "fmi2SetReal: unknown value reference %u (this FMU has 0..%d)",
              (unsigned)vr[k], NVAR - 1);
      return fmi2Error;
    }
    if (vr[k] >= NY) {
      log_msg(c, fmi2Error, "fmi2SetReal: %s (value reference %u) is an output; only the measurements "
              "(value references 0..%d) can be set", var_names[vr[k]], (unsigned)vr[k], NY - 1);
      return fmi2Error;
    }
    if (!is_finite(value[k])) {
      log_msg(c, fmi2Error, "fmi2SetReal: measurement %s = %g at t = %.17g is not finite; it was not set",
              var_names[vr[k]], value[k], c->time);
      return fmi2Error;
    }
  }
  for (k = 0; k < nvr; ++k) c->y[vr[k]] = value[k];
  c->fresh = 0;
  return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
  instance *c = (instance *)comp;
  fmi2Real dev;
  int rc;
  CHECK_INSTANCE(c);
  (void)noSetFMUStatePriorToCurrentPoint;
  if (c->phase != PHASE_STEP) return wrong_phase(c, "fmi2DoStep");
  dev = communicationStepSize - TS;
  if (!(dev <= STEP_RTOL * TS && -dev <= STEP_RTOL * TS)) {
    log_msg(c, fmi2Error, "fmi2DoStep: communication step size %.17g refused: this FMU runs the "
            "discrete observer at its fixed sample time Ts = %.17g only (the step it was generated "
            "for); set the master's communication step (output interval) to Ts",
            communicationStepSize, TS);
    return fmi2Error;
  }
  c->time = currentCommunicationPoint;
  rc = take_sample(c, &c->st, c->out, !c->started);
  if (rc != 0) return sample_failed(c, rc, "fmi2DoStep");
  c->started = 1;
  c->fresh = 1; /* the outputs are this sample's, held until new inputs are set */
  c->time = currentCommunicationPoint + communicationStepSize;
  return fmi2OK;
}

/* ---- no Integer, Boolean or String variables ---------------------------------------------- */
static fmi2Status no_variables(instance *c, size_t nvr, const char *fn) {
  if (c == NULL) return fmi2Error;
  if (nvr == 0) return fmi2OK;
  log_msg(c, fmi2Error, "%s: this FMU has no variables of that type (only Real)", fn);
  return fmi2Error;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
  (void)vr;
  (void)value;
  return no_variables((instance *)c, nvr, "fmi2GetInteger");
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
  (void)vr;
  (void)value;
  return no_variables((instance *)c, nvr, "fmi2GetBoolean");
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
  (void)vr;
  (void)value;
  return no_variables((instance *)c, nvr, "fmi2GetString");
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
  (void)vr;
  (void)value;
  return no_variables((instance *)c, nvr, "fmi2SetInteger");
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
  (void)vr;
  (void)value;
  return no_variables((instance *)c, nvr, "fmi2SetBoolean");
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
  (void)vr;
  (void)value;
  return no_variables((instance *)c, nvr, "fmi2SetString");
}

/* ---- capabilities this FMU does not have (modelDescription.xml says so) -------------------- */
static fmi2Status unsupported(instance *c, const char *fn) {
  if (c == NULL) return fmi2Error;
  log_msg(c, fmi2Error, "%s is not supported by this FMU", fn);
  return fmi2Error;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
  (void)FMUstate;
  return unsupported((instance *)c, "fmi2GetFMUstate");
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
  (void)FMUstate;
  return unsupported((instance *)c, "fmi2SetFMUstate");
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
  (void)FMUstate;
  return unsupported((instance *)c, "fmi2FreeFMUstate");
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
  (void)FMUstate;
  (void)size;
  return unsupported((instance *)c, "fmi2SerializedFMUstateSize");
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[],
                                 size_t size) {
  (void)FMUstate;
  (void)serializedState;
  (void)size;
  return unsupported((instance *)c, "fmi2SerializeFMUstate");
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
  (void)serializedState;
  (void)size;
  (void)FMUstate;
  return unsupported((instance *)c, "fmi2DeSerializeFMUstate");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
  (void)vUnknown_ref;
  (void)nUnknown;
  (void)vKnown_ref;
  (void)nKnown;
  (void)dvKnown;
  (void)dvUnknown;
  return unsupported((instance *)c, "fmi2GetDirectionalDerivative");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
  (void)vr;
  (void)nvr;
  (void)order;
  (void)value;
  return unsupported((instance *)c, "fmi2SetRealInputDerivatives (canInterpolateInputs is false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
  (void)vr;
  (void)nvr;
  (void)order;
  (void)value;
  return unsupported((instance *)c, "fmi2GetRealOutputDerivatives (maxOutputDerivativeOrder is 0)");
}

fmi2Status fmi2CancelStep(fmi2Component c) {
  return unsupported((instance *)c, "fmi2CancelStep (steps are never asynchronous)");
}

/* ---- status queries: fmi2DoStep never returns fmi2Pending or fmi2Discard ------------------- */
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
  (void)s;
  (void)value;
  return unsupported((instance *)c, "fmi2GetStatus");
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value) {
  instance *c = (instance *)comp;
  CHECK_INSTANCE(c);
  if (s != fmi2LastSuccessfulTime || value == NULL) return unsupported(c, "fmi2GetRealStatus of this kind");
  *value = c->time;
  return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
  (void)s;
  (void)value;
  return unsupported((instance *)c, "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Boolean *value) {
  instance *c = (instance *)comp;
  CHECK_INSTANCE(c);
  if (s != fmi2Terminated || value == NULL) return unsupported(c, "fmi2GetBooleanStatus of this kind");
  *value = fmi2False; /* the FMU never asks to end the simulation */
  return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
  (void)s;
  (void)value;
  return unsupported((instance *)c, "fmi2GetStringStatus");
}
"""
)
